"""What every ``coloc bench`` measurement shares: the default batch sizes and ``per_second``."""

from __future__ import annotations

import gc
import time
from collections.abc import Callable

BATCHES = (1, 64, 1024)
PCRB_ROW = "pcrb, one episode"  # the bound's computation (its own play of the episode and its recursion)


def per_second(fn: Callable[[], None], min_seconds: float, warm_up: int = 5) -> float:
    """Calls per second of ``fn`` over at least ``min_seconds`` (after warm-up calls and a full garbage
    collection: the setup of a large batch leaves a one-off collection of ~0.4 s that would otherwise land in
    the timed window, as timeit avoids by disabling the collector). ``warm_up`` calls, because a compiled
    kernel (the relay chains' numba pass) is compiled at its first use, which the first step of an episode
    may not reach (no platform measures at reset)."""
    for _ in range(warm_up):
        fn()
    gc.collect()
    count, start = 0, time.perf_counter()
    while True:
        fn()
        count += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return count / elapsed
