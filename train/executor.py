"""Run independent units of work (Monte Carlo blocks, seeds) locally or as Ray tasks.

Each unit receives everything it needs (including its own seed), so the
results are the same whichever executor runs it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def map_tasks(fn: Callable[..., Any], items: Sequence[tuple], executor: str = "local",
              address: str | None = None) -> list[Any]:
    """``[fn(*item) for item in items]``, on this process or on a Ray cluster."""
    from coloc_env.config import BadInput
    if executor == "local":
        return [fn(*item) for item in items]
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
        return ray.get([remote.remote(*item) for item in items])
    finally:
        if started:
            ray.shutdown()
