"""Every preset and a few compositions render a legible, non-blank ``rgb_array`` frame.

Each frame is also written to ``$COLOC_FRAMES_DIR`` (default ``/tmp/frames``) as a PNG, so that a
person can look at them (the issue asks that someone does before a change to the renderer lands).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import coloc_env
from coloc_env.rendering import (
    ELLIPSE_MIN_FRACTION,
    Link,
    Renderer,
    Scene,
    ellipse_magnification,
    nice_factor,
    separate_nodes,
)

DATASET6 = os.environ.get("COLOC_MRCLAM_DATA") or os.path.join(
    os.path.dirname(__file__), "..", "..", "..", "shared", "data", "mrclam", "MRCLAM_Dataset6")
FRAMES_DIR = os.environ.get("COLOC_FRAMES_DIR", "/tmp/frames")
MIN_WIDTH = 720

# Small but non-trivial settings: a few steps so that links, trails and particles exist.
PRESETS = {
    "bandwidth_fusion": {},
    "lossy_fusion": {},
    "relay_ukf": {},
    "gps_denied_nbp": {"num_particles": 60, "horizon": 6},
    "nlos_horizon": {"horizon": 40},
    "mrclam_relay": {"data": DATASET6, "window_steps": 40},
}
COMPOSITIONS = {
    "circles-relay-ukf_dcl": {"world": "circles", "network": "relay", "backend": "ukf_dcl"},
    "circles-broadcast-dnbp": {"world": "circles", "network": "broadcast",
                               "backend": {"name": "dnbp", "num_particles": 60}},
    "target_cv-bernoulli_delay-kalman": {"world": "target_cv", "network": "bernoulli_delay", "backend": "kalman"},
}


def _rollout_frame(env, steps: int) -> np.ndarray:
    """The frame after ``steps`` steps of seeded random actions from seed 3."""
    env.reset(seed=3)
    rng = np.random.default_rng(5)
    for agent in env.possible_agents:
        env.action_space(agent).seed(int(rng.integers(2**31)))
    for _ in range(steps):
        if not env.agents:
            break
        env.step({a: env.action_space(a).sample() for a in env.agents})
    return env.render()


def _check_frame(frame: np.ndarray, name: str) -> None:
    assert frame.ndim == 3 and frame.shape[2] == 3, frame.shape
    assert frame.shape[1] >= MIN_WIDTH, f"{name}: frame {frame.shape[1]} px wide, want >= {MIN_WIDTH}"
    assert frame.dtype == np.uint8
    assert frame.astype(float).var() > 100.0, f"{name}: frame is (nearly) blank"
    colours = np.unique(frame.reshape(-1, 3) // 32, axis=0)
    assert len(colours) >= 8, f"{name}: only {len(colours)} colour bins"
    os.makedirs(FRAMES_DIR, exist_ok=True)
    from matplotlib.image import imsave

    imsave(os.path.join(FRAMES_DIR, f"{name}.png"), frame)


@pytest.mark.parametrize("name", list(PRESETS))
def test_preset_frame_is_legible_and_not_blank(name):
    config = dict(PRESETS[name])
    if name == "mrclam_relay" and not os.path.isdir(DATASET6):
        pytest.skip(f"MRCLAM dataset 6 not found at {DATASET6} (set COLOC_MRCLAM_DATA)")
    env = coloc_env.parallel_env(name, render_mode="rgb_array", **config)
    _check_frame(_rollout_frame(env, steps=5), name)
    env.close()


def test_every_frame_of_an_env_has_the_same_size():
    """Video recorders need it, while the legend and notes change from step to step."""
    env = coloc_env.parallel_env("gps_denied_nbp", render_mode="rgb_array", num_particles=40, horizon=4)
    env.reset(seed=1)
    first = env.render()
    env.step({a: env.action_space(a).sample() for a in env.agents})
    assert env.render().shape == first.shape == (600, 960, 3)


@pytest.mark.parametrize("name", list(COMPOSITIONS))
def test_composition_frame_is_legible_and_not_blank(name):
    spec = coloc_env.compose(**COMPOSITIONS[name], horizon=20)
    env = coloc_env.parallel_env(spec, render_mode="rgb_array")
    _check_frame(_rollout_frame(env, steps=5), name)


def test_render_accepts_the_mode_rllib_passes_and_refuses_another():
    env = coloc_env.parallel_env("relay_ukf", render_mode="rgb_array", horizon=5)
    env.reset(seed=0)
    np.testing.assert_array_equal(env.render("rgb_array"), env.render())
    with pytest.raises(ValueError, match="render mode 'human' differs from this env's render_mode 'rgb_array'"):
        env.render("human")
    assert coloc_env.parallel_env("relay_ukf", horizon=5).render() is None


def _scene(covariance_std: float, span: float = 1000.0) -> Scene:
    return Scene(title="test", truth=np.array([[0.0, 0.0], [span, 0.0]]),
                 estimates=np.array([[1.0, 0.0], [span - 1.0, 0.0]]),
                 covariances=np.stack([np.eye(2) * covariance_std**2] * 2),
                 node_positions=np.array([[0.0, 0.0], [1.0, 0.0]]), node_labels=["a_0", "a_1"],
                 links=[Link(0, 1, 1.0, "x")], extent=(-10.0, span + 10.0, -10.0, 10.0))


def test_small_ellipses_are_magnified_by_a_stated_round_factor():
    span = 1000.0
    small = np.stack([np.eye(2) * 0.5**2])  # 2-sigma semi-axis 1 m on a 1 km map
    factor = ellipse_magnification(small, span)
    mantissa = factor / 10.0 ** np.floor(np.log10(factor))
    assert factor > 1.0 and min(abs(mantissa - m) for m in (1.0, 2.0, 5.0)) < 1e-9
    assert 2.0 * 0.5 * factor >= ELLIPSE_MIN_FRACTION * span  # now visible at the map's scale
    large = np.stack([np.eye(2) * 100.0**2])
    assert ellipse_magnification(large, span) == 1.0


@pytest.mark.parametrize(("ratio", "expected"), [(0.3, 1.0), (1.0, 1.0), (1.5, 2.0), (3.0, 5.0), (7.0, 10.0),
                                                  (11.0, 20.0), (49.0, 50.0), (51.0, 100.0)])
def test_nice_factor_is_the_next_1_2_5_number(ratio, expected):
    assert nice_factor(ratio) == pytest.approx(expected, rel=1e-12)


def test_magnified_legend_entry_names_the_factor():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from coloc_env.rendering import draw_scene

    figure = Figure(figsize=(9.6, 6.0), dpi=100)
    FigureCanvasAgg(figure)
    draw_scene(_scene(covariance_std=0.5), figure, agent_names=["a_0", "a_1"])
    texts = [t.get_text() for legend in figure.legends for t in legend.get_texts()]
    factor = ellipse_magnification(_scene(0.5).covariances, 1020.0)
    assert f"2\u03c3 ellipse \u00d7{factor:g} (enlarged)" in texts
    assert texts[:3] == ["estimate of (dot colour):", "a_0", "a_1"]


def test_separated_nodes_keep_a_minimum_distance_and_leave_spread_nodes_alone():
    crowded = np.array([[0.0, 0.0], [0.01, 0.0], [0.0, 0.0], [1.0, 1.0]])
    moved = separate_nodes(crowded, min_distance=0.3)
    distances = np.linalg.norm(moved[:, None] - moved[None], axis=-1)[np.triu_indices(4, 1)]
    assert distances.min() >= 0.3 - 1e-6
    spread = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(separate_nodes(spread, 0.3), spread, atol=1e-12)


def test_frames_have_the_renderers_size():
    renderer = Renderer("rgb_array", size=(8.0, 5.0), dpi=100)
    assert renderer.render(_scene(3.0)).shape == (500, 800, 3)


def test_the_inset_goes_to_a_corner_without_data():
    from coloc_env.rendering import emptiest_corner

    limits = (0.0, 100.0, 0.0, 100.0)
    everywhere_but_lower_left = np.array([[90.0, 90.0], [10.0, 90.0], [90.0, 10.0], [50.0, 50.0]])
    corner, crowd = emptiest_corner(everywhere_but_lower_left, limits, size=0.36)
    assert corner == (0.0, 0.0) and crowd == 0
    _, crowd = emptiest_corner(np.vstack([everywhere_but_lower_left, [[10.0, 10.0]]]), limits, size=0.36)
    assert crowd == 1
