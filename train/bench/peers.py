"""``coloc bench``'s comparisons with other libraries: VMAS's batched ``simple_spread`` (``bench_vmas``) and,
for relay_ukf, filterpy's ``UnscentedKalmanFilter`` doing one full-chain update per copy (``PEERS``) beside our
batched ``dcl_update`` doing the same work."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from train.bench.measure import BATCHES, per_second


def _relay_ukf_inputs(batch: int, platforms: int = 4):
    rng = np.random.default_rng(0)
    estimate = rng.normal(scale=20.0, size=(batch, platforms, 2))
    root = rng.normal(scale=0.3, size=(batch, 2 * platforms, 2 * platforms))
    cov = root @ np.swapaxes(root, -1, -2) + 0.1 * np.eye(2 * platforms)
    z = np.linalg.norm(estimate[:, 0] - estimate[:, 1], axis=-1) + 0.5
    return estimate, cov, z


def _relay_ukf_full_chain_update(batch: int, platforms: int = 4) -> Callable[[], None]:
    """One UKF-DCL range update relayed along the full chain 0 -> 1 -> 2 -> 3 for B copies, on synthetic
    dense covariances: the work of the filterpy peer, not the env's step (that is the estimator row)."""
    import estimators.ukf_relay as ukf

    estimate, cov, z = _relay_ukf_inputs(batch, platforms)
    chain = np.broadcast_to(np.arange(platforms), (batch, platforms))

    def step() -> None:
        ukf.dcl_update(estimate, cov, chain, np.full(batch, platforms), z, 1.0)

    return step


def _relay_ukf_filterpy_loop(batch: int, platforms: int = 4) -> Callable[[], None]:
    """The same range update by filterpy's ``UnscentedKalmanFilter``, one copy at a time (the peer)."""
    from train.reproduce.wang2019 import filterpy_ccl_update

    estimate, cov, z = _relay_ukf_inputs(batch, platforms)

    def step() -> None:
        for b in range(batch):
            filterpy_ccl_update(estimate[b], cov[b], 0, 1, float(z[b]), 1.0)

    return step


# Peers measured beside a scenario's estimator, each after the row of our estimator doing the peer's work:
# (label, factory(batch) -> step callable, our label, our factory).
PEERS: dict[str, tuple[str, Callable[[int], Callable[[], None]], str, Callable[[int], Callable[[], None]]]] = {
    "relay_ukf": ("filterpy UnscentedKalmanFilter loop", _relay_ukf_filterpy_loop,
                  "UKF-DCL full-chain update (peer's work)", _relay_ukf_full_chain_update),
}


def bench_vmas(min_seconds: float, batches=BATCHES) -> list[dict]:
    """VMAS's batched simple_spread (4 agents, CPU), the leading batched simulator, if installed."""
    try:
        import torch
        import vmas
    except ImportError:
        return []
    rows = []
    for batch in batches:
        env = vmas.make_env("simple_spread", num_envs=batch, device="cpu", continuous_actions=True, n_agents=4,
                            seed=0)
        env.reset()
        actions = [torch.zeros(batch, 2) for _ in range(4)]
        rate = per_second(lambda env=env, actions=actions: env.step(actions), min_seconds)
        rows.append({"scenario": "vmas simple_spread", "what": "vmas (torch, CPU)", "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * 4})
    return rows
