"""Every preset and a few compositions render a legible, non-blank ``rgb_array`` frame.

Each frame is also written to ``$COLOC_FRAMES_DIR`` (default ``/tmp/frames``) as a PNG, so that a
person can look at them before a change to the renderer lands.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import coloc_env
from coloc_env.rendering import (
    ELLIPSE_MIN_FRACTION,
    RELATIVE_VIEW_MAGNIFICATION,
    Link,
    Renderer,
    Scene,
    ellipse_magnification,
    nice_factor,
    separate_nodes,
)
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON

DATASET6 = MRCLAM_DATASET6
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
        pytest.skip(MRCLAM_SKIP_REASON)
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
    draw_scene(_scene(covariance_std=2.0), figure, agent_names=["a_0", "a_1"])
    texts = [t.get_text() for legend in figure.legends for t in legend.get_texts()]
    factor = ellipse_magnification(_scene(2.0).covariances, 1020.0)
    assert 1.0 < factor < RELATIVE_VIEW_MAGNIFICATION
    assert f"2\u03c3 ellipse \u00d7{factor:g} (enlarged)" in texts
    assert texts[:3] == ["estimate of (dot colour):", "a_0", "a_1"]


def test_agents_far_apart_with_tiny_errors_are_drawn_as_errors_at_true_scale():
    """Metre errors on a kilometre map (an enlargement of 50x or more): the map shows estimate - truth, the truths
    at (0, 0), the ellipses unmagnified, and the view is metres wide, not the kilometres between the agents."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from coloc_env.rendering import ELLIPSE_SIGMA, draw_scene

    scene = _scene(covariance_std=0.5)
    assert ellipse_magnification(scene.covariances, 1020.0) >= RELATIVE_VIEW_MAGNIFICATION
    figure = Figure(figsize=(9.6, 6.0), dpi=100)
    FigureCanvasAgg(figure)
    draw_scene(scene, figure, agent_names=["a_0", "a_1"])
    ax = figure.axes[0]
    assert "estimate \u2212 truth" in ax.get_xlabel() and ax.get_xlabel().endswith("[m]")
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    reach = 1.0 + ELLIPSE_SIGMA * 0.5  # the 1 m errors and their 2-sigma ellipses
    assert x0 < -reach and x1 > reach and y0 < -ELLIPSE_SIGMA * 0.5 and y1 > ELLIPSE_SIGMA * 0.5
    assert max(x1 - x0, y1 - y0) < 10.0
    texts = [t.get_text() for legend in figure.legends for t in legend.get_texts()]
    assert "2\u03c3 ellipse (true scale)" in texts and "true position (each at 0, 0)" in texts


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


def _drawn(scene: Scene, agent_names):
    """``scene`` drawn on a 960 x 600 figure: (figure, map axes, network axes or None)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from coloc_env.rendering import draw_scene

    figure = Figure(figsize=(9.6, 6.0), dpi=100)
    FigureCanvasAgg(figure)
    draw_scene(scene, figure, agent_names=agent_names)
    figure.canvas.draw()
    axes = figure.axes  # the map and the network (an inset is a child of the map's)
    return figure, axes[0], (axes[1] if len(axes) > 1 else None)


def _rolled_scene(env, steps: int) -> Scene:
    _rollout_frame(env, steps)
    return env.scenario.scene(0)


def _overlap(a, b) -> float:
    return max(min(a.x1, b.x1) - max(a.x0, b.x0), 0.0) * max(min(a.y1, b.y1) - max(a.y0, b.y0), 0.0)


CROWDED = {
    "bandwidth_fusion": lambda: coloc_env.parallel_env("bandwidth_fusion", render_mode="rgb_array"),
    "bandwidth_fusion-8": lambda: coloc_env.parallel_env("bandwidth_fusion", num_agents=8, budget=10,
                                                         render_mode="rgb_array"),
    "bandwidth_fusion-16": lambda: coloc_env.parallel_env("bandwidth_fusion", num_agents=16, budget=20,
                                                          render_mode="rgb_array"),
    "lossy_fusion-8": lambda: coloc_env.parallel_env("lossy_fusion", num_agents=8, render_mode="rgb_array"),
    "nlos_horizon": lambda: coloc_env.parallel_env("nlos_horizon", horizon=40, render_mode="rgb_array"),
    "drift-8-relay-kalman": lambda: coloc_env.parallel_env(coloc_env.compose(
        world={"name": "drift", "num_agents": 8}, network="relay", backend="kalman", horizon=20),
        render_mode="rgb_array"),
}


@pytest.mark.parametrize("name", list(CROWDED))
def test_network_labels_do_not_overlap_each_other_or_the_nodes(name):
    """Link labels and node names: no two overlap and none covers a node; a label left out is counted
    in the panel (or all are hidden, said in the legend), and the legend says what link colour and
    width stand for."""
    env = CROWDED[name]()
    scene = _rolled_scene(env, steps=5)
    figure, _, net = _drawn(scene, env.possible_agents)
    renderer = figure.canvas.get_renderer()
    link_words = {link.label for link in scene.links if link.label}
    node_words = set(scene.node_labels)
    texts = [t for t in net.texts if t.get_visible() and t.get_text()]
    link_texts = [t for t in texts if t.get_text() in link_words and t.get_text() not in node_words]
    node_texts = [t for t in texts if t.get_text() in node_words]
    assert len(node_texts) == len(scene.node_labels), f"{name}: a node without its name"
    labels = link_texts + node_texts
    boxes = [t.get_window_extent(renderer) for t in labels]
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert _overlap(boxes[i], boxes[j]) == 0.0, \
                f"{name}: labels {labels[i].get_text()!r} and {labels[j].get_text()!r} overlap"
    centres, radii = [], []
    for collection in net.collections:
        for offset, size in zip(collection.get_offsets(), np.broadcast_to(collection.get_sizes(),
                                                                           len(collection.get_offsets())),
                                strict=True):
            centres.append(net.transData.transform(offset))
            radii.append(0.5 * np.sqrt(size) * figure.dpi / 72.0)
    assert len(centres) == len(scene.node_labels)
    for text, box in zip(labels, boxes, strict=True):
        for (x, y), r in zip(centres, radii, strict=True):
            nearest = np.clip([x, y], [box.x0, box.y0], [box.x1, box.y1])
            assert np.hypot(nearest[0] - x, nearest[1] - y) >= r, f"{name}: {text.get_text()!r} covers a node"
    legend = [t.get_text() for lg in figure.legends for t in lg.get_texts()]
    labelled = sum(1 for link in scene.links if link.label)
    notes = " ".join(t.get_text() for t in net.texts)
    if len(link_texts) < labelled:
        assert (f"labels of {labelled - len(link_texts)} of {labelled} links left out" in notes
                or f"(link labels hidden: {len(scene.links)} links)" in legend), \
            f"{name}: {labelled - len(link_texts)} link labels missing without a word"
    assert any(t.startswith("link colour and width:") for t in legend), legend
    env.close()


def test_crowded_links_hide_their_labels_and_the_legend_says_so():
    names = [f"n_{i}" for i in range(8)]
    from coloc_env.rendering import MAX_LINK_LABELS, ring_layout

    links = [Link(i, j, float((i + j) % 3), "abc") for i in range(8) for j in range(8) if i != j]
    assert len(links) > MAX_LINK_LABELS
    scene = Scene(title="crowded", truth=np.zeros((1, 2)), estimates=np.zeros((8, 2)),
                  node_positions=ring_layout(8), node_labels=names, links=links, link_value_max=2.0,
                  link_value_name="things")
    figure, _, net = _drawn(scene, names)
    assert not [t for t in net.texts if t.get_text() == "abc"]
    legend = [t.get_text() for lg in figure.legends for t in lg.get_texts()]
    assert f"(link labels hidden: {len(links)} links)" in legend
    assert "link colour and width: things" in legend and {"1", "2"} <= set(legend)


def _inside_with_margin(points: np.ndarray, ax, fraction: float, what: str) -> None:
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    margin = fraction * max(x1 - x0, y1 - y0)
    points = np.atleast_2d(points)
    assert np.all(points[:, 0] >= x0 + margin) and np.all(points[:, 0] <= x1 - margin), \
        f"{what} {points.round(1).tolist()} not inside x {x0:.1f}..{x1:.1f} with {margin:.1f} m to spare"
    assert np.all(points[:, 1] >= y0 + margin) and np.all(points[:, 1] <= y1 - margin), \
        f"{what} {points.round(1).tolist()} not inside y {y0:.1f}..{y1:.1f} with {margin:.1f} m to spare"


TARGET_WORLDS = {
    "target_cv-bernoulli_delay-kalman": {"world": "target_cv", "network": "bernoulli_delay", "backend": "kalman"},
    "drift-ideal-centralized_lmmse": {"world": "drift", "network": "ideal", "backend": "centralized_lmmse"},
}


def _ellipse_extremes(scene: Scene, ax_span: float) -> np.ndarray:
    from coloc_env.rendering import ELLIPSE_SIGMA, _ellipse_points

    factor = ellipse_magnification(scene.covariances, ax_span)
    return np.concatenate([_ellipse_points(m, c, scale=ELLIPSE_SIGMA * factor)
                           for m, c in zip(scene.estimates, scene.covariances, strict=True)])


@pytest.mark.parametrize("name", list(TARGET_WORLDS))
def test_a_target_world_frames_the_target_the_agents_and_their_ellipses(name):
    """The target moves away from the agents: after 20 steps the map still holds it, every estimate,
    every ellipse and every agent with 5 % of the map to spare."""
    env = coloc_env.parallel_env(coloc_env.compose(**TARGET_WORLDS[name], horizon=40), render_mode="rgb_array")
    scene = _rolled_scene(env, steps=20)
    figure, ax, _ = _drawn(scene, env.possible_agents)
    _check_frame(env.render(), f"{name}-k20")
    _inside_with_margin(scene.truth, ax, 0.05, "target")
    _inside_with_margin(scene.estimates, ax, 0.05, "estimates")
    x0, x1 = ax.get_xlim()
    _inside_with_margin(_ellipse_extremes(scene, x1 - x0), ax, 0.02, "ellipses")
    _inside_with_margin(env.scenario.world.positions()[0], ax, 0.05, "agents")
    env.close()


@pytest.mark.parametrize("name", list(TARGET_WORLDS))
def test_a_scene_with_sensors_and_no_extent_is_framed_round_what_it_draws(name):
    """The view a target world's scene gets when it names where the agents are and sets no extent:
    the agents (triangles, in the legend), the target and the estimates fill the map, with a margin."""
    import dataclasses

    env = coloc_env.parallel_env(coloc_env.compose(**TARGET_WORLDS[name], horizon=40), render_mode="rgb_array")
    sensors = env.scenario.world.positions()
    scene = dataclasses.replace(_rolled_scene(env, steps=20), sensors=sensors[0], extent=None)
    figure, ax, _ = _drawn(scene, env.possible_agents)
    everything = np.vstack([scene.truth, scene.estimates, sensors[0]])
    for points, what in ((scene.truth, "target"), (scene.estimates, "estimates"), (sensors[0], "agents")):
        _inside_with_margin(points, ax, 0.05, what)
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert np.ptp(everything, axis=0).max() >= 0.6 * max(x1 - x0, y1 - y0), "the map is mostly empty"
    legend = [t.get_text() for lg in figure.legends for t in lg.get_texts()]
    assert "agent position" in legend
    from matplotlib.image import imsave

    figure.canvas.draw()
    os.makedirs(FRAMES_DIR, exist_ok=True)
    imsave(os.path.join(FRAMES_DIR, f"{name}-with-sensors.png"), np.asarray(figure.canvas.buffer_rgba())[..., :3])
    env.close()
