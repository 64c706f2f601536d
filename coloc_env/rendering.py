"""One renderer for every scenario.

A scenario describes what to draw for one copy as a :class:`Scene`; the
renderer turns it into an RGB array (``render_mode="rgb_array"``) or shows it
in a matplotlib window (``render_mode="human"``). Two panels: the estimation
view (truth, estimates, covariance ellipses, optional particles and trails)
and the network view (nodes and the links of the current step, coloured by
what they carried).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

AGENT_COLOURS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
                 "tab:pink", "tab:olive", "tab:cyan", "tab:gray"]


@dataclass
class Link:
    """A link of the current step from node ``source`` to node ``target``.

    ``value`` in [0, ``Scene.link_value_max``] sets its colour (0 = carried
    nothing, drawn faint); ``label`` is written at its middle.
    """

    source: int
    target: int
    value: float
    label: str = ""


@dataclass
class Scene:
    """What the renderer draws for one environment copy (2-D projections, metres).

    ``truth`` (K, 2): true positions of the tracked objects; ``estimates``
    (N, 2) and ``covariances`` (N, 2, 2): each agent's estimate and its
    covariance (drawn as a 2-sigma ellipse); ``trails`` (K, T, 2): recent true
    path; ``particles`` (N, P, 2): particle clouds where the estimator has
    them; ``node_positions`` (N, 2): where the network panel draws each agent;
    ``links``: what moved over the network this step.
    """

    title: str
    truth: np.ndarray
    estimates: np.ndarray | None = None
    covariances: np.ndarray | None = None
    trails: np.ndarray | None = None
    particles: np.ndarray | None = None
    node_positions: np.ndarray | None = None
    node_labels: list[str] = field(default_factory=list)
    links: list[Link] = field(default_factory=list)
    link_value_max: float = 1.0
    link_value_name: str = ""
    directed: bool = True
    extent: tuple[float, float, float, float] | None = None
    notes: list[str] = field(default_factory=list)


def _ellipse_points(mean: np.ndarray, cov: np.ndarray, scale: float = 2.0, count: int = 48) -> np.ndarray:
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    radii = scale * np.sqrt(np.clip(vals, 0.0, None))
    angle = np.linspace(0.0, 2.0 * np.pi, count)
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return mean + (circle * radii) @ vecs.T


def draw_scene(scene: Scene, figure) -> None:
    """Draw ``scene`` on a matplotlib ``figure`` (cleared first)."""
    import matplotlib as mpl

    figure.clear()
    has_network = scene.node_positions is not None
    axes = figure.subplots(1, 2, gridspec_kw={"width_ratios": [3, 2]}) if has_network else [figure.subplots()]
    ax = axes[0]
    if scene.trails is not None:
        for trail in scene.trails:
            ax.plot(trail[:, 0], trail[:, 1], color="0.6", lw=1)
    if scene.particles is not None:
        for i, cloud in enumerate(scene.particles):
            ax.scatter(cloud[:, 0], cloud[:, 1], s=2, alpha=0.3, color=AGENT_COLOURS[i % len(AGENT_COLOURS)])
    truth = np.atleast_2d(scene.truth)
    ax.scatter(truth[:, 0], truth[:, 1], marker="*", s=160, color="black", label="truth", zorder=5)
    if scene.estimates is not None:
        for i, est in enumerate(np.atleast_2d(scene.estimates)):
            colour = AGENT_COLOURS[i % len(AGENT_COLOURS)]
            label = scene.node_labels[i] if i < len(scene.node_labels) else f"agent {i}"
            ax.scatter([est[0]], [est[1]], s=40, color=colour, label=label, zorder=4)
            if scene.covariances is not None:
                pts = _ellipse_points(est, scene.covariances[i])
                ax.plot(pts[:, 0], pts[:, 1], color=colour, lw=1)
    if scene.extent is not None:
        ax.set_xlim(scene.extent[0], scene.extent[1])
        ax.set_ylim(scene.extent[2], scene.extent[3])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(scene.title, fontsize=10)
    ax.legend(loc="upper left", fontsize=7)
    for n, note in enumerate(scene.notes):
        ax.text(0.01, 0.02 + 0.05 * n, note, transform=ax.transAxes, fontsize=8)

    if has_network:
        net = axes[1]
        pos = np.asarray(scene.node_positions, float)
        cmap = mpl.colormaps["viridis"]
        for link in scene.links:
            a, b = pos[link.source], pos[link.target]
            frac = float(np.clip(link.value / max(scene.link_value_max, 1e-12), 0.0, 1.0))
            colour = cmap(frac) if link.value > 0 else (0.8, 0.8, 0.8, 0.6)
            d = b - a
            # Offset directed links sideways so that i->j and j->i do not overlap.
            normal = np.array([-d[1], d[0]]) / (np.linalg.norm(d) + 1e-12) * (0.04 if scene.directed else 0.0)
            if scene.directed:
                net.annotate("", xy=b + normal - 0.12 * d, xytext=a + normal + 0.12 * d,
                             arrowprops={"arrowstyle": "->", "color": colour, "lw": 1 + 2 * frac})
            else:
                net.plot([a[0], b[0]], [a[1], b[1]], color=colour, lw=1 + 2 * frac)
            if link.label:
                mid = 0.5 * (a + b) + 2.5 * normal
                net.text(mid[0], mid[1], link.label, fontsize=6, ha="center", va="center")
        for i, p in enumerate(pos):
            net.scatter([p[0]], [p[1]], s=300, color=AGENT_COLOURS[i % len(AGENT_COLOURS)], zorder=3)
            label = scene.node_labels[i] if i < len(scene.node_labels) else str(i)
            net.text(p[0], p[1], label.split("_")[-1], ha="center", va="center", color="white", zorder=4)
        net.set_aspect("equal")
        net.axis("off")
        title = "network"
        if scene.link_value_name:
            title += f" (colour: {scene.link_value_name}, max {scene.link_value_max:g})"
        net.set_title(title, fontsize=9)
        margin = 0.3
        net.set_xlim(pos[:, 0].min() - margin, pos[:, 0].max() + margin)
        net.set_ylim(pos[:, 1].min() - margin, pos[:, 1].max() + margin)
    figure.tight_layout()


def ring_layout(count: int) -> np.ndarray:
    """Node positions on a unit circle, node 0 at the top, clockwise."""
    angle = np.pi / 2 - 2 * np.pi * np.arange(count) / count
    return np.stack([np.cos(angle), np.sin(angle)], axis=1)


class Renderer:
    """Keeps one figure per env; ``rgb_array`` draws off-screen, ``human`` shows a window."""

    def __init__(self, render_mode: str | None, size: tuple[float, float] = (9.0, 4.5), dpi: int = 80):
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.render_mode = render_mode
        self.size, self.dpi = size, dpi
        self._figure = None

    def render(self, scene: Scene) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self.render_mode == "rgb_array":
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            if self._figure is None:
                self._figure = Figure(figsize=self.size, dpi=self.dpi)
                FigureCanvasAgg(self._figure)
            draw_scene(scene, self._figure)
            self._figure.canvas.draw()
            return np.asarray(self._figure.canvas.buffer_rgba())[..., :3].copy()
        import matplotlib.pyplot as plt

        if self._figure is None:
            plt.ion()
            self._figure = plt.figure(figsize=self.size, dpi=self.dpi)
        draw_scene(scene, self._figure)
        self._figure.canvas.draw_idle()
        plt.pause(0.001)
        return None

    def close(self) -> None:
        if self._figure is not None and self.render_mode == "human":
            import matplotlib.pyplot as plt

            plt.close(self._figure)
        self._figure = None
