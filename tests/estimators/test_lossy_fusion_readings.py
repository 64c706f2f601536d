"""fu2017 (B)'s readings of the compensation (29): where they must agree, and the ordering the lag predicts."""

import numpy as np
import pytest

import estimators.lossy_fusion as lf
from tests.estimators.test_lossy_fusion import P0, X0, episodes


@pytest.mark.parametrize("num_agents", [2, 4])
def test_with_every_link_on_time_every_reading_is_the_paper_s(num_agents):
    """alpha1 = 1: the weights (29) are (1, 0, 0) and every held packet is the fresh one (age 0), so forward
    prediction by the possible ages, by the known age and the printed reading all fuse x_i(k|k)."""
    model, sim, _ = episodes(4, 1, num_agents=num_agents, on_time_probability=1.0, late_probability=0.0, horizon=30)
    assert np.all(sim["outcome"] == lf.ON_TIME)
    paper = lf.distributed_filter(model, X0, P0, sim["z"], sim["outcome"])
    for reading, spread in (("forward", True), ("forward", False), ("age_aware", True)):
        other = lf.distributed_filter(model, X0, P0, sim["z"], sim["outcome"], reading=reading, forward_spread=spread)
        np.testing.assert_allclose(other[0], paper[0], rtol=0, atol=1e-9, err_msg=reading)
        np.testing.assert_allclose(other[1], paper[1], rtol=0, atol=1e-9, err_msg=reading)


def test_forward_reading_spread_is_what_separates_it_from_the_printed_covariance():
    """Over lossy links the forward reading's covariance is the printed sum_a w_a P_a plus the (PSD) spread of
    the three predictions: at every slot its compensated covariance dominates the printed one, while the
    compensated estimate is the same (the followers' filters and the held packets do not depend on the fusion);
    only the fusion weights (30), hence the fused estimate, change."""
    model, sim, _ = episodes(3, 2, num_agents=3, horizon=20)
    state = {s: lf.distributed_initial(model, X0, P0, (3,)) for s in (True, False)}
    for k in range(20):
        for s in state:
            state[s] = lf.distributed_step(model, state[s], sim["z"][:, k], sim["outcome"][:, k], reading="forward",
                                           forward_spread=s)
        np.testing.assert_allclose(state[True].compensated, state[False].compensated, rtol=0, atol=1e-9)
        gap = state[True].compensated_cov - state[False].compensated_cov
        assert np.linalg.eigvalsh(gap).min() > -1e-9
    assert np.abs(state[True].fused - state[False].fused).max() > 1e-3


@pytest.mark.parametrize("num_agents", [2, 4])
def test_predicting_the_held_packet_forward_beats_using_it_as_current(num_agents):
    """The target moves ~14 m per slot: a held packet a slots old lags it by a slots. The printed reading keeps
    that whole lag (E[A^2] v^2 in the follower's error); predicting by the possible ages removes its mean,
    leaving Var(A) v^2, and the spread term tells the fusion (30) how much of it is left. Paired over 120 seeded
    runs of the paper's links, forward's MSE is below the printed reading's, the 95 % interval excluding 0."""
    model, sim, H = episodes(120, 9, num_agents=num_agents)
    mse = {r: np.sum(((lf.distributed_filter(model, X0, P0, sim["z"], sim["outcome"], reading=r)[0] - sim["truth"])
                      @ H.T) ** 2, axis=-1).mean(axis=1) for r in ("current", "forward")}
    diff = mse["forward"] - mse["current"]
    assert diff.mean() + 1.96 * diff.std(ddof=1) / np.sqrt(len(diff)) < 0


def test_an_unknown_reading_is_named():
    model, sim, _ = episodes(1, 0, horizon=5)
    with pytest.raises(ValueError, match=r"reading must be one of \('current', 'forward', 'age_aware'\), got 'x'"):
        lf.distributed_filter(model, X0, P0, sim["z"], sim["outcome"], reading="x")
