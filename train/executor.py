"""Run independent units of work (Monte Carlo blocks, seeds) locally or as Ray tasks.

Each unit receives everything it needs (including its own seed), so the
results are the same whichever executor runs it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def map_tasks(fn: Callable[..., Any], items: Sequence[tuple], executor: str = "local",
              address: str | None = None, progress: Callable[[int, int], None] | None = None) -> list[Any]:
    """``[fn(*item) for item in items]``, on this process or on a Ray cluster. ``progress(done, total)`` is called
    as each unit finishes (on Ray in the order they finish; the results keep the order of ``items``), and a unit
    that raises stops the map with its exception as soon as it finishes."""
    from coloc_env.config import BadInput

    items = list(items)
    if executor == "local":
        results = []
        for item in items:
            results.append(fn(*item))
            if progress:
                progress(len(results), len(items))
        return results
    if executor != "ray":
        raise BadInput(f"executor must be 'local' or 'ray', got {executor!r}")
    try:
        import ray
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise BadInput("executor 'ray' needs the ray extra: pip install 'coloc[ray]'") from exc
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(fn)
        references = [remote.remote(*item) for item in items]
        pending, done = list(references), 0
        while pending:
            finished, pending = ray.wait(pending, num_returns=1)
            ray.get(finished)  # raises a failed unit's exception now rather than after every other unit
            done += len(finished)
            if progress:
                progress(done, len(items))
        return ray.get(references)
    finally:
        if started:
            ray.shutdown()
