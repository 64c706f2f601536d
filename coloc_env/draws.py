"""Counter-based uniforms: one key per copy, a value per (key, counters), no loop over copies.

A network decides at each step whether each packet is lost; drawing those
uniforms per copy from a generator would loop over copies at every step, and
drawing a whole episode at reset costs K x rounds x N x N floats per copy. A
counter-based draw needs neither: each copy draws one 64-bit key at reset from
its own generator, and the uniform of event (k, round, i, j) is a hash of the
key and the counters (SplitMix64's finalizer, Steele, Lea, Flood, "Fast
splittable pseudorandom number generators", OOPSLA 2014; the same mixing is
the output function of numpy's SFC/SplitMix seeding). The value of an event
depends only on its copy's key and its counters, so copy b of a batch equals
the same copy alone, bit for bit.
"""

from __future__ import annotations

import functools

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _mix(z: np.ndarray) -> np.ndarray:
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


def draw_keys(rngs, dtype=np.uint64) -> np.ndarray:
    """One key per generator (B,), each drawn from its own generator."""
    return np.array([rng.integers(0, 2**63, dtype=np.int64) for rng in rngs], dtype=np.int64).astype(dtype)


@functools.lru_cache(maxsize=64)
def _cell_offsets(shape: tuple[int, ...]) -> np.ndarray:
    """GOLDEN * (idx + 1) of every cell of ``shape`` (read-only; the same for every call of that shape)."""
    cells = np.arange(int(np.prod(shape, dtype=np.int64)), dtype=np.uint64)
    offsets = (_GOLDEN * (cells + np.uint64(1))).reshape(shape)
    offsets.flags.writeable = False
    return offsets


def uniforms(keys: np.ndarray, counters: tuple, shape: tuple[int, ...]) -> np.ndarray:
    """Uniforms in [0, 1) of shape (B, *shape): entry [b, idx] hashes keys[b], ``counters`` and idx.

    ``counters`` are integers or (B,) integer arrays (e.g. the step k of each copy, a round number).
    """
    # Every operand is an array of at least one dimension, so uint64 products wrap (modulo 2^64, the hash's
    # arithmetic) without numpy's scalar overflow warning, and no errstate context is needed.
    keys = np.asarray(keys, dtype=np.uint64)
    B = keys.shape[0]
    z = keys.copy()
    for counter in counters:
        c = np.asarray(counter, dtype=np.int64).reshape(-1).astype(np.uint64)  # (1,) or (B,): broadcasts
        z = _mix(z + _GOLDEN * (c + np.uint64(1)))
    z = _mix(z.reshape((B,) + (1,) * len(shape)) + _cell_offsets(tuple(int(n) for n in shape)))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)
