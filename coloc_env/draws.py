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
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_MASK = (1 << 64) - 1
_GOLDEN_INT, _M1_INT, _M2_INT = int(_GOLDEN), int(_M1), int(_M2)
_SMALL_BATCH = 8  # copies up to which the counters are mixed on Python ints


def _mix_in_place(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finalizer on uint64 ``z``, overwriting it (an array the caller owns)."""
    z ^= z >> _S30
    z *= _M1
    z ^= z >> _S27
    z *= _M2
    z ^= z >> _S31
    return z


def _mix_int(z: int) -> int:
    """The finalizer of ``_mix_in_place`` on one Python int, modulo 2^64 as uint64 arithmetic wraps."""
    z = ((z ^ (z >> 30)) * _M1_INT) & _MASK
    z = ((z ^ (z >> 27)) * _M2_INT) & _MASK
    return z ^ (z >> 31)


def _counter_chain(keys: np.ndarray, counters: tuple) -> np.ndarray:
    """keys (B,) mixed with every counter in turn: the per-copy part of ``uniforms``."""
    B = keys.shape[0]
    values = [np.asarray(counter, dtype=np.int64).reshape(-1) for counter in counters]
    if B <= _SMALL_BATCH and all(len(c) in (1, B) for c in values):
        # a few copies: a numpy call costs more than the whole chain on Python ints (the same values)
        columns = [c.tolist() * (B if len(c) == 1 else 1) for c in values]
        out = []
        for b, z in enumerate(keys.tolist()):
            for column in columns:
                z = _mix_int((z + _GOLDEN_INT * ((column[b] + 1) & _MASK)) & _MASK)
            out.append(z)
        return np.array(out, dtype=np.uint64)
    z = keys.copy()
    for c in values:
        z = _mix_in_place(z + _GOLDEN * (c.astype(np.uint64) + np.uint64(1)))  # (1,) or (B,): broadcasts
    return z


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
    z = _counter_chain(keys, counters)
    z = _mix_in_place(z.reshape((B,) + (1,) * len(shape)) + _cell_offsets(tuple(int(n) for n in shape)))
    z >>= _S11
    return z.astype(np.float64) * (1.0 / 9007199254740992.0)
