"""One renderer for every scenario and composition.

A scenario describes what to draw for one copy as a ``Scene``; the
renderer turns it into an RGB array (``render_mode="rgb_array"``) or shows it
in a matplotlib window (``render_mode="human"``). Every frame has the same
layout, so that presets and compositions look alike:

* the title (the scenario and the time) across the top, wrapped, never cut;
* the map (left): true positions (hollow black circles), each agent's
  estimate (a filled dot in the agent's colour, drawn above the truth), a
  thin segment from truth to estimate, the covariance ellipses (2 sigma,
  magnified by a 1-2-5 factor named in the legend when the largest would be
  under 2 % of the map), particle clouds, recent true paths, landmarks and,
  where the truth is a tracked target, the agents themselves (triangles);
  the view holds the truth, the estimates, their ellipses, the agents and
  the landmarks with 8 % of the map to spare (the scene's extent is the
  least it shows); equal metres on both axes, the limits widened (never
  narrowed) to the panel's shape, so a long thin scene is not squashed into
  a strip. Where the scene has particles and one cloud is too small to see,
  an inset in the map's emptiest corner shows that agent's particles and
  ellipse at true scale. Where the agents are so far apart that the ellipses
  would need a ``RELATIVE_VIEW_MAGNIFICATION`` enlargement or more (metre
  errors kilometres apart), the map shows each estimate minus its truth
  instead: every truth at (0, 0), the ellipses at true scale;
* the network (middle): one node per participant, labelled beside it with
  its full name, coloured as on the map (white: a node that is not an
  agent; a red ring: a node with a status such as a GPS fault), and the
  links of the current step, their colour and width showing what they
  carried. The names and the link labels are placed when the frame is drawn,
  where none overlaps another or covers a node (a link label beside its
  arrow, crossing no other link where it can); a label that finds no room
  is left out and counted under the panel, and with more than
  ``MAX_LINK_LABELS`` links none is written (the legend says so);
* the legend (right): each agent's colour, every mark, what an arrow and a
  dashed link mean, and what the link colours and widths count (with
  samples);
* the notes (bottom), below the panels.

The figure has exactly two axes (map and network; the inset is a child of
the map); title, legend and notes are figure-level artists placed by
matplotlib's constrained layout, so none overlaps a panel.

Frames are 960 x 600 pixels by default (``Renderer``), legible when
scaled to 720 pixels wide.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field

import numpy as np

# tab10, then tab20's light shades: 20 distinct agent colours (bandwidth_fusion allows 16 UAVs)
AGENT_COLOURS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
                 "tab:pink", "tab:olive", "tab:cyan", "tab:gray",
                 "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94", "#f7b6d2", "#dbdb8d",
                 "#9edae5", "#c7c7c7"]
MAX_LINK_LABELS = 24  # more labelled links than this would cover the network panel
NON_AGENT_COLOUR = "white"  # drawn with a grey edge: no agent colour (tab:gray is one) looks like it
FAULT_COLOUR = "crimson"
ELLIPSE_SIGMA = 2.0
# An ellipse whose largest 2-sigma semi-axis is below this fraction of the map's span is magnified
# (by a 1-2-5 factor) so that its largest one spans about ELLIPSE_TARGET_FRACTION.
ELLIPSE_MIN_FRACTION = 0.02
ELLIPSE_TARGET_FRACTION = 0.05
MAP_MARGIN = 0.08  # of the map's largest side, kept free round everything drawn
MAX_NOTE_LINES = 5
LEGEND_ROWS = 30  # legend entries that fit one column of a 600-pixel frame
PANELS_FRACTION = 0.74  # of the figure's width, left of the legend
INSET_SIZE = 0.36  # the particle inset's side, as a fraction of the map's
FONT_SIZE = 10
# Ellipses that would need this enlargement or more (the largest 2-sigma semi-axis under 0.1 % of the map) are
# drawn in error coordinates instead (``_draw_relative_map``): agents kilometres apart with metre errors.
RELATIVE_VIEW_MAGNIFICATION = 50.0


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

    ``truth`` (K, 2): true positions of the tracked objects (the agents
    themselves, or one target); ``estimates`` (N, 2) and ``covariances``
    (N, 2, 2): each agent's estimate and its covariance (drawn as a 2-sigma
    ellipse); ``estimate_labels``: the legend's name of each estimate (default:
    the env's ``possible_agents``, else ``node_labels``); ``trails`` (K, T, 2):
    recent true path; ``particles`` (N, P, 2): particle clouds where the
    estimator has them; ``landmarks`` (L, 2): fixed known beacons;
    ``node_positions`` (M, 2): where the network panel draws each node (any
    scale: the panel fits them), ``node_labels`` their names and
    ``node_status`` a short word per node (e.g. "GPS fault", "" for none),
    drawn as a red ring round the node and named in the legend; ``links``: what moved over the network this step.
    ``sensors`` (N, 2): where the agents are when ``truth`` is a target they track (drawn as triangles in
    the agents' colours). ``extent`` (x0, x1, y0, y1) is the least the map shows: the map grows beyond
    it where something drawn (truth, estimates, their ellipses, sensors, landmarks) would lie outside it or
    closer than ``MAP_MARGIN`` to its edge; without it the map frames all of them and the trails.
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
    landmarks: np.ndarray | None = None
    estimate_labels: list[str] | None = None
    node_status: list[str] = field(default_factory=list)
    sensors: np.ndarray | None = None


def _ellipse_points(mean: np.ndarray, cov: np.ndarray, scale: float = ELLIPSE_SIGMA, count: int = 48) -> np.ndarray:
    """Points of the ellipse {x : (x - mean)^T cov^-1 (x - mean) = scale^2}."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    radii = scale * np.sqrt(np.clip(vals, 0.0, None))
    angle = np.linspace(0.0, 2.0 * np.pi, count)
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return mean + (circle * radii) @ vecs.T


def nice_factor(ratio: float) -> float:
    """The smallest of 1, 2, 5, 10, 20, 50, ... that is at least ``ratio`` (a magnification a reader can read)."""
    if not np.isfinite(ratio) or ratio <= 1.0:
        return 1.0
    exponent = np.floor(np.log10(ratio))
    for mantissa in (1.0, 2.0, 5.0, 10.0):
        if mantissa * 10.0**exponent >= ratio:
            return float(mantissa * 10.0**exponent)
    return float(10.0 ** (exponent + 1))


def ellipse_magnification(covariances: np.ndarray | None, span: float) -> float:
    """The factor applied to the 2-sigma ellipses so that the largest is visible on a map ``span`` metres wide.

    1 when the largest 2-sigma semi-axis is already at least ``ELLIPSE_MIN_FRACTION`` of the span;
    otherwise a 1-2-5 number that brings it to about ``ELLIPSE_TARGET_FRACTION`` (stated in the legend).
    """
    if covariances is None or len(covariances) == 0 or not span > 0:
        return 1.0
    cov = np.asarray(covariances, float)
    largest = ELLIPSE_SIGMA * float(np.sqrt(np.clip(np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, -1, -2))),
                                                    0.0, None).max()))
    if not np.isfinite(largest) or largest >= ELLIPSE_MIN_FRACTION * span:
        return 1.0
    if largest <= 0.0:
        return 1.0
    return nice_factor(ELLIPSE_TARGET_FRACTION * span / largest)


def separate_nodes(positions: np.ndarray, min_distance: float, iterations: int = 50) -> np.ndarray:
    """``positions`` moved apart until no two are closer than ``min_distance`` (deterministic).

    Nodes of the network panel sit where the agents are, and agents flying in formation would
    overlap; each pass pushes every too-close pair apart along the line joining them (coincident
    nodes along a fixed direction per pair), so the picture keeps who is near whom.
    """
    pos = np.array(positions, float)
    count = len(pos)
    for _ in range(iterations):
        moved = False
        for i in range(count):
            for j in range(i + 1, count):
                d = pos[j] - pos[i]
                dist = float(np.hypot(*d))
                if dist >= min_distance:
                    continue
                angle = 2.0 * np.pi * (i * count + j) / max(count * count, 1)
                direction = d / dist if dist > 1e-12 else np.array([np.cos(angle), np.sin(angle)])
                push = 0.5 * (min_distance - dist) * direction
                pos[i] -= push
                pos[j] += push
                moved = True
        if not moved:
            break
    return pos


def _finite_points(points: list) -> np.ndarray:
    arrays = [np.asarray(p, float).reshape(-1, 2) for p in points if p is not None and np.size(p)]
    stacked = np.concatenate(arrays) if arrays else np.zeros((0, 2))
    return stacked[np.all(np.isfinite(stacked), axis=1)]


def _map_limits(scene: Scene, points: list) -> tuple[float, float, float, float]:
    """The map's box: around everything in ``points`` (what is drawn) with a margin of ``MAP_MARGIN``
    of its largest side (at least 1 m), and never less than the scene's ``extent``."""
    stacked = _finite_points(points)
    if not len(stacked):
        return tuple(float(v) for v in scene.extent) if scene.extent is not None else (-1.0, 1.0, -1.0, 1.0)
    low, high = stacked.min(axis=0), stacked.max(axis=0)
    if scene.extent is not None:
        x0, x1, y0, y1 = (float(v) for v in scene.extent)
        span = max(x1 - x0, y1 - y0, float((high - low).max()))
    else:
        span = float((high - low).max())
    pad = max(MAP_MARGIN * span, 1.0)
    box = (low[0] - pad, high[0] + pad, low[1] - pad, high[1] + pad)
    if scene.extent is None:
        return box
    return (min(x0, box[0]), max(x1, box[1]), min(y0, box[2]), max(y1, box[3]))


def fit_aspect(limits: tuple[float, float, float, float], height_over_width: float) -> tuple[float, ...]:
    """``limits`` (x0, x1, y0, y1) widened symmetrically on the shorter side so that, drawn with equal
    metres on both axes, the box has the panel's shape ``height_over_width`` (never narrowed: nothing
    drawn is cut, and a long thin scene is not squashed into a strip)."""
    x0, x1, y0, y1 = limits
    width, height = max(x1 - x0, 1e-9), max(y1 - y0, 1e-9)
    if height / width < height_over_width:
        grow = 0.5 * (width * height_over_width - height)
        return (x0, x1, y0 - grow, y1 + grow)
    grow = 0.5 * (height / height_over_width - width)
    return (x0 - grow, x1 + grow, y0, y1)


def _panel_shape(ax) -> float:
    """Height over width of the panel ``ax`` on its figure, in inches."""
    box = ax.get_position()
    return float((box.height * ax.figure.get_figheight()) / max(box.width * ax.figure.get_figwidth(), 1e-9))


def _agent_colour(index: int) -> str:
    return AGENT_COLOURS[index % len(AGENT_COLOURS)]


def _estimate_labels(scene: Scene, agent_names, count: int) -> list[str]:
    for names in (scene.estimate_labels, agent_names, scene.node_labels):
        if names is not None and len(names) >= count:
            return [str(n) for n in names[:count]]
    return [f"agent {i}" for i in range(count)]


def _draw_map(ax, scene: Scene, agent_names, handles: list, agent_handles: list) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    truth = np.atleast_2d(np.asarray(scene.truth, float))
    estimates = None if scene.estimates is None else np.atleast_2d(np.asarray(scene.estimates, float))
    sensors = None if scene.sensors is None or not np.size(scene.sensors) else \
        np.atleast_2d(np.asarray(scene.sensors, float))
    # what the map must show; a recent path only where the scene sets no extent (it may run off the map)
    drawn = [truth, estimates, scene.landmarks, sensors] + ([scene.trails] if scene.extent is None else [])
    x0, x1, y0, y1 = _map_limits(scene, drawn)
    span = max(x1 - x0, y1 - y0)
    magnification = ellipse_magnification(scene.covariances, span)
    ellipses = []
    if estimates is not None and scene.covariances is not None:
        ellipses = [_ellipse_points(est, np.asarray(scene.covariances[i], float), scale=ELLIPSE_SIGMA * magnification)
                    for i, est in enumerate(estimates)]
        # the ellipses inside too, with the margin; a diverged one (far larger than the scene) widens the
        # view by at most the scene's size each side, so that the rest is not shrunk to a dot
        span_now = max(x1 - x0, y1 - y0)
        low, high = np.array([x0 - span_now, y0 - span_now]), np.array([x1 + span_now, y1 + span_now])
        x0, x1, y0, y1 = _map_limits(scene, drawn + [np.clip(e, low, high) for e in ellipses])

    relative = estimates is not None and scene.covariances is not None and sensors is None and \
        (len(estimates) == len(truth) or len(truth) == 1) and magnification >= RELATIVE_VIEW_MAGNIFICATION and \
        (scene.particles is None or not np.size(scene.particles))
    if relative:
        _draw_relative_map(ax, scene, truth, estimates, _estimate_labels(scene, agent_names, len(estimates)),
                           handles, agent_handles)
        return
    if scene.trails is not None and np.size(scene.trails):
        for trail in np.asarray(scene.trails, float):
            ax.plot(trail[:, 0], trail[:, 1], color="0.65", lw=1.2, zorder=1)
        handles.append(Line2D([], [], color="0.65", lw=1.2, label="true path (recent)"))
    if scene.landmarks is not None and np.size(scene.landmarks):
        marks = np.atleast_2d(np.asarray(scene.landmarks, float))
        ax.scatter(marks[:, 0], marks[:, 1], marker="s", s=28, facecolor="0.85", edgecolor="0.3", lw=0.8, zorder=2)
        handles.append(Line2D([], [], ls="", marker="s", ms=6, mfc="0.85", mec="0.3", label="landmark"))
    if scene.particles is not None and np.size(scene.particles):
        for i, cloud in enumerate(np.asarray(scene.particles, float)):
            ax.scatter(cloud[:, 0], cloud[:, 1], s=4, alpha=0.35, color=_agent_colour(i), lw=0, zorder=2)
        handles.append(Line2D([], [], ls="", marker=".", ms=6, color="0.4", alpha=0.6, label="particles (belief)"))

    self_localisation = estimates is not None and len(estimates) == len(truth) and sensors is None
    truth_label = "true position" if self_localisation or len(truth) > 1 else "target (truth)"
    if sensors is not None:
        for i, p in enumerate(sensors):
            ax.scatter([p[0]], [p[1]], marker="^", s=70, color=_agent_colour(i), edgecolor="black", lw=0.7, zorder=5)
        handles.append(Line2D([], [], ls="", marker="^", ms=8, mfc="0.8", mec="black", mew=0.7,
                              label="agent position"))
    ax.scatter(truth[:, 0], truth[:, 1], marker="o", s=110, facecolor="none", edgecolor="black", lw=1.4, zorder=5)
    handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc="none", mec="black", mew=1.4, label=truth_label))

    if estimates is not None:
        labels = _estimate_labels(scene, agent_names, len(estimates))
        for i, est in enumerate(estimates):
            colour = _agent_colour(i)
            if self_localisation:
                ax.plot([truth[i, 0], est[0]], [truth[i, 1], est[1]], color=colour, lw=0.9, zorder=4)
            ax.scatter([est[0]], [est[1]], s=34, color=colour, edgecolor="white", lw=0.6, zorder=6)
            if ellipses:
                ax.plot(ellipses[i][:, 0], ellipses[i][:, 1], color=colour, lw=1.3, zorder=4)
            agent_handles.append(Line2D([], [], ls="", marker="o", ms=6, color=colour, label=labels[i]))
        if self_localisation:
            handles.append(Line2D([], [], color="0.3", lw=0.9, label="error (truth to estimate)"))
        if scene.covariances is not None:
            what = "2\u03c3 ellipse" + (f" \u00d7{magnification:g} (enlarged)" if magnification > 1 else "")
            handles.append(Line2D([], [], color="0.3", lw=1.3, label=what))

    shape = _panel_shape(ax)
    x0, x1, y0, y1 = fit_aspect((x0, x1, y0, y1), shape)  # widen the shorter side: never a strip
    inset_corner = None
    if estimates is not None and wants_belief_inset(scene, (x0, x1, y0, y1)):
        inset_corner, crowd = emptiest_corner(_finite_points([truth, estimates, scene.trails, sensors]),
                                              (x0, x1, y0, y1), INSET_SIZE)
        if crowd:  # widen the map to the right so that the inset hides nothing
            x1 = x1 + INSET_SIZE / (1.0 - INSET_SIZE) * (x1 - x0)
            x0, x1, y0, y1 = fit_aspect((x0, x1, y0, y1), shape)
            inset_corner = (1.0 - INSET_SIZE, 1.0 - INSET_SIZE)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    if inset_corner is not None:
        _draw_belief_inset(ax, scene, _estimate_labels(scene, agent_names, len(estimates)), inset_corner)
        handles.append(_inset_handle())
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(nbins=5))
        formatter = ScalarFormatter(useOffset=False)
        formatter.set_scientific(False)
        axis.set_major_formatter(formatter)
    ax.tick_params(labelsize=FONT_SIZE - 1)
    ax.set_xlabel("x [m]", fontsize=FONT_SIZE)
    ax.set_ylabel("y [m]", fontsize=FONT_SIZE)
    ax.set_title("estimates", fontsize=FONT_SIZE + 1)
    ax.grid(True, color="0.92", lw=0.6, zorder=0)


def _draw_relative_map(ax, scene: Scene, truth: np.ndarray, estimates: np.ndarray, labels: list[str],
                       handles: list, agent_handles: list) -> None:
    """The map in error coordinates: each estimate minus its truth, every truth at (0, 0), the 2-sigma
    ellipses at true scale, equal metres on both axes. Drawn instead of the positions when the agents are
    so far apart that the errors and ellipses would be invisible (``RELATIVE_VIEW_MAGNIFICATION``)."""
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    own = truth if len(truth) == len(estimates) else np.repeat(truth[:1], len(estimates), axis=0)
    offsets = estimates - own
    ellipses = [_ellipse_points(offsets[i], np.asarray(scene.covariances[i], float)) for i in range(len(offsets))]
    ax.axhline(0.0, color="0.8", lw=0.8, zorder=1)
    ax.axvline(0.0, color="0.8", lw=0.8, zorder=1)
    ax.scatter([0.0], [0.0], marker="o", s=110, facecolor="none", edgecolor="black", lw=1.4, zorder=5)
    for i, offset in enumerate(offsets):
        colour = _agent_colour(i)
        ax.plot([0.0, offset[0]], [0.0, offset[1]], color=colour, lw=0.9, zorder=4)
        ax.plot(ellipses[i][:, 0], ellipses[i][:, 1], color=colour, lw=1.3, zorder=4)
        ax.scatter([offset[0]], [offset[1]], s=34, color=colour, edgecolor="white", lw=0.6, zorder=6)
        agent_handles.append(Line2D([], [], ls="", marker="o", ms=6, color=colour, label=labels[i]))
    what = "true position (each at 0, 0)" if len(truth) == len(estimates) else "target (truth, at 0, 0)"
    handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc="none", mec="black", mew=1.4, label=what))
    handles.append(Line2D([], [], color="0.3", lw=0.9, label="error (truth to estimate)"))
    handles.append(Line2D([], [], color="0.3", lw=1.3, label="2\u03c3 ellipse (true scale)"))
    points = np.vstack([np.zeros((1, 2)), offsets, *ellipses])
    points = points[np.all(np.isfinite(points), axis=1)]
    reach = max(float(np.abs(points).max()) * (1.0 + MAP_MARGIN), 1e-3)
    x0, x1, y0, y1 = fit_aspect((-reach, reach, -reach, reach), _panel_shape(ax))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(nbins=5))
    ax.tick_params(labelsize=FONT_SIZE - 1)
    ax.set_xlabel("estimate \u2212 truth, x [m]", fontsize=FONT_SIZE)
    ax.set_ylabel("estimate \u2212 truth, y [m]", fontsize=FONT_SIZE)
    apart = float(np.ptp(np.vstack([truth, estimates]), axis=0).max())
    ax.set_title(f"estimate errors (agents up to {apart / 1000.0:.3g} km apart)" if apart >= 1000.0 else
                 f"estimate errors (agents up to {apart:.3g} m apart)", fontsize=FONT_SIZE)
    ax.grid(True, color="0.92", lw=0.6, zorder=0)


def belief_zoom(truth: np.ndarray, estimates: np.ndarray, particles: np.ndarray,
                covariances: np.ndarray | None) -> tuple[int, float]:
    """(agent, half-width in m) of the inset that shows one particle cloud at its true scale.

    The agent is the one whose estimate is furthest from its truth (the cloud worth looking at; agent
    0 when the truth is one shared target); the half-width holds its truth, its 2-sigma ellipse and
    98 % of its particles.
    """
    self_localisation = len(truth) == len(estimates)
    errors = np.linalg.norm(estimates - truth, axis=1) if self_localisation else np.zeros(len(estimates))
    agent = int(np.argmax(errors))
    cloud = np.asarray(particles[agent], float)
    reach = [1.2 * errors[agent], 1.1 * float(np.quantile(np.linalg.norm(cloud - estimates[agent], axis=1), 0.98))]
    if covariances is not None:
        largest = float(np.sqrt(np.clip(np.linalg.eigvalsh(np.asarray(covariances[agent], float)), 0.0, None).max()))
        reach.append(1.2 * ELLIPSE_SIGMA * largest)
    return agent, max(*reach, 0.5)


def wants_belief_inset(scene: Scene, limits: tuple[float, float, float, float]) -> bool:
    """Whether the frame shows one particle cloud at true scale: the scene has particles and the cloud
    of ``belief_zoom`` is under a tenth of the map wide (invisible at the map's scale)."""
    if scene.estimates is None or scene.particles is None or not np.size(scene.particles):
        return False
    truth, estimates = np.atleast_2d(np.asarray(scene.truth, float)), np.atleast_2d(np.asarray(scene.estimates, float))
    _, half = belief_zoom(truth, estimates, np.asarray(scene.particles, float), scene.covariances)
    x0, x1, y0, y1 = limits
    return 2.0 * half < 0.1 * max(x1 - x0, y1 - y0)


def emptiest_corner(points: np.ndarray, limits: tuple[float, float, float, float],
                    size: float) -> tuple[tuple[float, float], int]:
    """The corner (lower-left in axes fractions) of a ``size`` x ``size`` inset holding the fewest of
    ``points`` on a map with ``limits``, and how many it holds (upper right first on ties)."""
    x0, x1, y0, y1 = limits
    u, v = (points[:, 0] - x0) / (x1 - x0), (points[:, 1] - y0) / (y1 - y0)
    gap = 0.04
    corners = [(1 - size, 1 - size), (0.0, 1 - size), (1 - size, 0.0), (0.0, 0.0)]
    crowd = [int(np.sum((u >= cx - gap) & (u <= cx + size + gap) & (v >= cy - gap) & (v <= cy + size + gap)))
             for cx, cy in corners]
    best = int(np.argmin(crowd))
    return corners[best], crowd[best]


def _draw_belief_inset(ax, scene: Scene, labels: list[str], corner: tuple[float, float]) -> None:
    """One agent's particles, truth, estimate and 2-sigma ellipse at their true scale, in an inset at
    ``corner`` of the map ``ax`` (particle clouds are metres wide on maps of hundreds of metres)."""
    truth, estimates = np.atleast_2d(np.asarray(scene.truth, float)), np.atleast_2d(np.asarray(scene.estimates, float))
    agent, half = belief_zoom(truth, estimates, np.asarray(scene.particles, float), scene.covariances)
    cx, cy = corner
    size = INSET_SIZE
    inset = ax.inset_axes([cx + 0.015, cy + 0.015, size - 0.03, size - 0.03], zorder=10)
    colour, centre = _agent_colour(agent), estimates[agent]
    cloud = np.asarray(scene.particles[agent], float)
    inset.scatter(cloud[:, 0], cloud[:, 1], s=6, alpha=0.5, color=colour, lw=0)
    own_truth = truth[agent:agent + 1] if len(truth) == len(estimates) else truth
    inset.scatter(own_truth[:, 0], own_truth[:, 1], marker="o", s=70, facecolor="none", edgecolor="black", lw=1.3,
                  zorder=5)
    inset.scatter([centre[0]], [centre[1]], s=28, color=colour, edgecolor="white", lw=0.6, zorder=6)
    if scene.covariances is not None:
        pts = _ellipse_points(centre, np.asarray(scene.covariances[agent], float))
        inset.plot(pts[:, 0], pts[:, 1], color=colour, lw=1.2)
    inset.set_xlim(centre[0] - half, centre[0] + half)
    inset.set_ylim(centre[1] - half, centre[1] + 1.6 * half)  # headroom for the caption
    inset.set_aspect("equal", adjustable="box")
    inset.set_xticks([])
    inset.set_yticks([])
    inset.text(0.5, 0.98, f"zoom: {labels[agent]}\n{2 * half:.3g} m wide", transform=inset.transAxes,
               ha="center", va="top", fontsize=FONT_SIZE - 2,
               bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85})


def link_colour_samples(scene: Scene) -> list[float]:
    """The link values the legend shows a colour for: those drawn this step (at most 5, spread over
    their range) and the scale's maximum."""
    values = sorted({float(link.value) for link in scene.links if link.value > 0} | {float(scene.link_value_max)})
    if len(values) > 5:
        values = [values[int(round(i))] for i in np.linspace(0, len(values) - 1, 5)]
    return values


def _link_width(frac: float, crowded: bool) -> float:
    """Line width (points) of a link carrying ``frac`` of the scale's maximum (thinner when crowded)."""
    return (0.6 + 1.4 * frac) if crowded else (1.0 + 2.0 * frac)


class _NetworkLabels:
    """The texts of the network panel, placed when the figure is drawn (after the layout: where they hit
    nothing). An artist of the panel drawn before its texts (``draw``, lowest zorder) moves them."""

    def __init__(self, net, centres: np.ndarray, names: list[str], node_radius_pt: float, node_font: float,
                 directed: bool):
        from matplotlib.artist import Artist

        self.net, self.centres, self.node_radius_pt, self.directed = net, centres, node_radius_pt, directed
        self.node_texts = [self._text(name, node_font, 7, "node-label",
                                      {"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7})
                           for name in names]
        # (text, from, to, source node, target node), from and to where the link is drawn
        self.links: list[tuple] = []
        self.note = net.text(0.5, 0.0, "", transform=net.transAxes, fontsize=FONT_SIZE - 2, ha="center", va="top",
                             color="0.3", gid="link-label-note", visible=False)
        self.note.set_in_layout(False)
        self.written = self.left_out = 0

        placer = Artist()
        placer.draw = lambda renderer: self.place(renderer)
        placer.set_zorder(-100)  # before every text of the panel
        placer.set_in_layout(False)
        net.add_artist(placer)

    def _text(self, label: str, font: float, zorder: int, gid: str, bbox: dict):
        text = self.net.text(0.0, 0.0, label, fontsize=font, ha="center", va="center", zorder=zorder,
                             color="black", bbox=bbox, gid=gid)
        text.set_in_layout(False)  # inside the panel: the layout need not make room for it
        return text

    def add_link(self, label: str, start: np.ndarray, end: np.ndarray, source: int, target: int) -> None:
        if len(label) > 16:  # a long label on two or more short lines fits between the links
            label = "\n".join(textwrap.wrap(label, 14)) or label
        text = self._text(label, FONT_SIZE - 2, 4, "link-label",
                          {"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85})
        self.links.append((text, start, end, source, target))

    def place(self, renderer) -> None:
        """Each node's name beside it on the first free side (away from the layout's middle first); each
        link label at the first free place along its link (beside its arrow when directed, crossing no
        other link if it can), or nowhere, counted in a note under the panel."""
        net = self.net
        to_px = net.transData.transform
        to_data = net.transData.inverted().transform
        px_per_pt = net.figure.dpi / 72.0
        frame = tuple(net.get_window_extent(renderer).extents)
        centres = to_px(self.centres) if len(self.centres) else np.zeros((0, 2))
        radius = self.node_radius_pt * px_per_pt
        occupied = [(x - radius, y - radius, x + radius, y + radius) for x, y in centres]

        middle = centres.mean(axis=0) if len(centres) else np.zeros(2)
        for i, text in enumerate(self.node_texts):
            w, h = _text_size(text, renderer, 0.1)
            away = centres[i] - middle
            base = float(np.arctan2(away[1], away[0])) if np.hypot(*away) > 1.0 else np.pi / 4
            best, best_cost = None, np.inf
            for turn in (0, 30, -30, 60, -60, 90, -90, 120, -120, 150, -150, 180):
                angle = base + np.radians(turn)
                u = np.array([np.cos(angle), np.sin(angle)])
                for gap in (3.0, 10.0):
                    c = centres[i] + u * (radius + gap) + 0.5 * u * np.array([w, h])
                    box = (c[0] - w / 2, c[1] - h / 2, c[0] + w / 2, c[1] + h / 2)
                    cost = _collision(box, occupied, frame)
                    if cost < best_cost - 1e-9:
                        best, best_cost = (c, box), cost
                    if cost == 0.0:
                        break
                if best_cost == 0.0:
                    break
            text.set_position(to_data(best[0]))
            occupied.append(best[1])

        self.written = self.left_out = 0
        # nearer the sender first (many links end at one receiver), then further along
        steps = ((0.4, 0.5, 0.3, 0.6, 0.25, 0.7, 0.2, 0.75, 0.15, 0.85) if self.directed
                 else (0.5, 0.62, 0.38, 0.72, 0.28, 0.8, 0.2))
        drawn = {(source, target) for *_, source, target in self.links}
        # points along every labelled link, so that a label goes where it crosses no other link if it can
        along = np.linspace(0.0, 1.0, 25)[:, None]
        lines = [to_px(start) + along * (to_px(end) - to_px(start)) for _, start, end, *_ in self.links]
        sizes = [_text_size(text, renderer, 0.15) for text, *_ in self.links]
        for number in sorted(range(len(self.links)), key=lambda k: -sizes[k][0] * sizes[k][1]):  # largest first
            text, start, end, source, target = self.links[number]
            a, b = to_px(start), to_px(end)
            d = b - a
            normal = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-9)
            w, h = sizes[number]
            half = 0.5 * (abs(normal[0]) * w + abs(normal[1]) * h) + 1.0  # centre to edge across the link
            if self.directed:  # beside its own arrow; the other side only where no arrow comes back
                sides = [half, half + 6.0, half + 14.0] + ([] if (target, source) in drawn
                                                           else [-half, -half - 6.0, -half - 14.0])
            else:  # on the line, else beside it
                sides = [0.0, half, -half, half + 8.0, -half - 8.0]
            others = np.concatenate([p for k, p in enumerate(lines) if k != number] or [np.zeros((0, 2))])
            placed = None
            for avoid_lines, side, t in ((v, s, t) for v in (True, False) for s in sides for t in steps):
                c = a + t * d + side * normal
                box = (c[0] - w / 2, c[1] - h / 2, c[0] + w / 2, c[1] + h / 2)
                if _collision(box, occupied, frame) > 0.0:
                    continue
                if avoid_lines and np.any((others[:, 0] > box[0]) & (others[:, 0] < box[2])
                                          & (others[:, 1] > box[1]) & (others[:, 1] < box[3])):
                    continue
                if not avoid_lines and len(others) and np.min(np.hypot(*(others - c).T)) < _segment_distance(c, a, b):
                    continue  # on other links and nearer one of them than its own: it would be read as theirs
                placed = (c, box)
                break
            text.set_visible(placed is not None)
            if placed is None:
                self.left_out += 1
                continue
            text.set_position(to_data(placed[0]))
            occupied.append(placed[1])
            self.written += 1
        self.note.set_text(f"labels of {self.left_out} of {len(self.links)} links left out (no room)")
        self.note.set_visible(self.left_out > 0)


def _segment_distance(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance from ``point`` to the segment from ``a`` to ``b``."""
    d = b - a
    t = float(np.clip(np.dot(point - a, d) / max(float(np.dot(d, d)), 1e-12), 0.0, 1.0))
    return float(np.hypot(*(point - a - t * d)))


def _boxes_overlap(a, b) -> float:
    """Area (pixels^2) that two display boxes (x0, y0, x1, y1) share."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return max(w, 0.0) * max(h, 0.0)


def _collision(box, occupied: list, frame) -> float:
    """How much ``box`` hits the ``occupied`` boxes or leaves ``frame`` (0: free)."""
    inside = _boxes_overlap(box, frame)
    outside = (box[2] - box[0]) * (box[3] - box[1]) - inside
    return outside + sum(_boxes_overlap(box, other) for other in occupied)


def _text_size(text, renderer, pad: float) -> tuple[float, float]:
    """Width and height (pixels) of ``text`` with its white box (``pad`` in font sizes) and a pixel to spare."""
    extent = text.get_window_extent(renderer)
    pad_px = 2.0 * pad * text.get_fontsize() * text.figure.dpi / 72.0 + 2.0
    return extent.width + pad_px, extent.height + pad_px


def _draw_network(net, scene: Scene, agent_names, handles: list, colour_handles: list) -> _NetworkLabels:
    """The nodes and links of ``scene`` on the panel ``net``; returns the texts to place once the figure
    is drawn (``_NetworkLabels``)."""
    import matplotlib as mpl
    from matplotlib.lines import Line2D

    pos = np.atleast_2d(np.asarray(scene.node_positions, float))
    span = float(np.ptp(pos, axis=0).max()) if len(pos) > 1 else 1.0
    span = span if span > 1e-9 else 1.0
    pos = (pos - 0.5 * (pos.min(axis=0) + pos.max(axis=0))) / span  # unit-size, centred, whatever the scale
    pos = separate_nodes(pos, min_distance=min(0.32, 2.2 / max(len(pos), 1)))  # a ring of 16 keeps its shape
    cmap = mpl.colormaps["viridis"]
    value_max = max(float(scene.link_value_max), 1e-12)
    names = [str(n) for n in scene.node_labels] + [str(i) for i in range(len(scene.node_labels), len(pos))]
    agent_index = {name: i for i, name in enumerate(agent_names or [])}
    crowded = len(scene.links) > MAX_LINK_LABELS
    many_nodes = len(pos) > 12
    node_size = 100.0 if many_nodes else 150.0

    pending = _NetworkLabels(net, pos, names, node_radius_pt=0.5 * np.sqrt(node_size) + 1.2,
                             node_font=FONT_SIZE - 2 if many_nodes else FONT_SIZE - 1, directed=scene.directed)
    for link in scene.links:
        a, b = pos[link.source], pos[link.target]
        frac = float(np.clip(link.value / value_max, 0.0, 1.0))
        colour = cmap(frac) if link.value > 0 else (0.75, 0.75, 0.75, 0.8)
        d = b - a
        # Offset directed links sideways so that i->j and j->i do not overlap.
        normal = np.array([-d[1], d[0]]) / (np.linalg.norm(d) + 1e-12) * (0.03 if scene.directed else 0.0)
        style = "-|>" if scene.directed else "-"
        net.annotate("", xy=b + normal, xytext=a + normal,
                     arrowprops={"arrowstyle": style, "color": colour, "lw": _link_width(frac, crowded),
                                 "shrinkA": 9, "shrinkB": 9, "mutation_scale": 8 if crowded else 12,
                                 "linestyle": "-" if link.value > 0 else "--"}, zorder=2)
        if link.label and not crowded:
            pending.add_link(link.label, a + normal, b + normal, int(link.source), int(link.target))
    status = list(scene.node_status) + [""] * (len(pos) - len(scene.node_status))
    for i, p in enumerate(pos):
        index = agent_index.get(names[i], i if not agent_index and i < len(AGENT_COLOURS) else None)
        colour = _agent_colour(index) if index is not None else NON_AGENT_COLOUR
        ring = FAULT_COLOUR if status[i] else ("white" if index is not None else "0.35")
        net.scatter([p[0]], [p[1]], s=node_size, color=colour, edgecolor=ring, lw=2.2 if status[i] else 1.2,
                    zorder=6)
    margin = 0.45  # room for the labels beside the outer nodes
    limits = (pos[:, 0].min() - margin, pos[:, 0].max() + margin, pos[:, 1].min() - 0.6 * margin,
              pos[:, 1].max() + 0.6 * margin)
    x0, x1, y0, y1 = fit_aspect(limits, _panel_shape(net))
    net.set_xlim(x0, x1)
    net.set_ylim(y0, y1)
    net.set_aspect("equal", adjustable="box")
    net.axis("off")
    net.set_title("network (this step)", fontsize=FONT_SIZE + 1)

    arrow = "arrow: message sender \u2192 receiver" if scene.directed else "line: link between two nodes"
    handles.append(Line2D([], [], color=cmap(0.7), lw=2, marker=">" if scene.directed else None, ms=5,
                          label=arrow))
    handles.append(Line2D([], [], color=(0.75, 0.75, 0.75), lw=1, ls="--", label="link that carried nothing"))
    if crowded and any(link.label for link in scene.links):
        handles.append(Line2D([], [], ls="", label=f"(link labels hidden: {len(scene.links)} links)"))
    if any(s for s in status):
        words = ", ".join(sorted({s for s in status if s}))
        handles.append(Line2D([], [], ls="", marker="o", ms=8, mfc="0.8", mec=FAULT_COLOUR, mew=2,
                              label=f"red ring: {words}"))
    if any(i not in agent_index for i in names) and agent_index:
        handles.append(Line2D([], [], ls="", marker="o", ms=8, mfc=NON_AGENT_COLOUR, mec="0.35",
                              label="node (not an agent)"))

    label = scene.link_value_name or "link value"
    colour_handles.append(Line2D([], [], ls="", label="\n".join(textwrap.wrap(f"link colour and width: {label}", 34))))
    for value in link_colour_samples(scene):
        frac = float(np.clip(value / value_max, 0.0, 1.0))
        colour_handles.append(Line2D([], [], color=cmap(frac), lw=_link_width(frac, crowded), label=f"{value:g}"))
    return pending


def _header(text: str):
    from matplotlib.lines import Line2D

    return Line2D([], [], ls="", label=text)


def draw_scene(scene: Scene, figure, agent_names: list[str] | None = None) -> None:
    """Draw ``scene`` on a matplotlib ``figure`` (cleared first); ``agent_names`` are the env's
    ``possible_agents`` (the legend's names of the estimates and the colours of the network's nodes).

    The figure holds two axes, the map and the network; the title, the legend (right) and the notes
    (bottom) are figure-level texts that the constrained layout makes room for, so none overlaps a panel.
    """
    figure.clear()
    figure.set_layout_engine("constrained")
    has_network = scene.node_positions is not None
    width_px = figure.get_figwidth() * figure.dpi
    # the title spans the panels only (the legend takes the right quarter from the top)
    wrap = max(40, int(PANELS_FRACTION * width_px / (0.62 * (FONT_SIZE + 2) * figure.dpi / 72.0)))
    figure.suptitle("\n".join(textwrap.wrap(scene.title, wrap)), x=0.5 * PANELS_FRACTION, fontsize=FONT_SIZE + 2)

    handles: list = []
    agent_handles: list = []
    network_handles: list = []
    colour_handles: list = []
    if has_network:
        ax, net = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1.25, 1.0]})
    else:
        ax = figure.subplots()
    _draw_map(ax, scene, agent_names, handles, agent_handles)
    if has_network:
        _draw_network(net, scene, agent_names, network_handles, colour_handles)

    entries = [_header("estimate of (dot colour):"), *agent_handles, _header("marks:"), *handles]
    if has_network:
        entries += [_header("network:"), *network_handles, *colour_handles]
    columns = 1 if len(entries) <= LEGEND_ROWS else 2  # many agents (bandwidth_fusion allows 16)
    legend = figure.legend(handles=entries, loc="outside right upper", fontsize=FONT_SIZE - 1, frameon=False,
                           handlelength=1.6, labelspacing=0.3, borderaxespad=0.2, ncols=columns)
    for text, entry in zip(legend.get_texts(), entries, strict=True):
        if entry.get_linestyle() in ("None", "", " ") and entry.get_marker() in ("None", None, "", " "):
            text.set_fontweight("bold")  # section headers and the colour scale's name

    notes = [str(n) for n in scene.notes]
    if len(notes) > MAX_NOTE_LINES:
        notes = notes[: MAX_NOTE_LINES - 1] + [f"(+{len(notes) - MAX_NOTE_LINES + 1} more notes)"]
    footer_wrap = max(60, int(width_px / (0.62 * (FONT_SIZE - 1) * figure.dpi / 72.0)))
    lines = [line for note in notes for line in textwrap.wrap(note, footer_wrap)][:MAX_NOTE_LINES]
    if lines:
        figure.supxlabel("\n".join(lines), x=0.01, ha="left", fontsize=FONT_SIZE - 1, family="monospace",
                         linespacing=1.3)


def _inset_handle():  # noqa: N802 - a legend handle
    from matplotlib.lines import Line2D

    return Line2D([], [], ls="", marker="s", ms=8, mfc="white", mec="black", label="inset: one belief at true scale")


def ring_layout(count: int) -> np.ndarray:
    """Node positions on a unit circle, node 0 at the top, clockwise."""
    angle = np.pi / 2 - 2 * np.pi * np.arange(count) / count
    return np.stack([np.cos(angle), np.sin(angle)], axis=1)


class Renderer:
    """Keeps one figure per env; ``rgb_array`` draws off-screen, ``human`` shows a window.

    The default 9.6 x 6.0 in at 100 dpi gives 960 x 600 pixel frames (every frame of an env the
    same size, as video recorders need).
    """

    def __init__(self, render_mode: str | None, size: tuple[float, float] = (9.6, 6.0), dpi: int = 100):
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.render_mode = render_mode
        self.size, self.dpi = size, dpi
        self._figure = None

    def render(self, scene: Scene, agent_names: list[str] | None = None) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self.render_mode == "rgb_array":
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            if self._figure is None:
                self._figure = Figure(figsize=self.size, dpi=self.dpi)
                FigureCanvasAgg(self._figure)
            draw_scene(scene, self._figure, agent_names)
            self._figure.canvas.draw()
            return np.asarray(self._figure.canvas.buffer_rgba())[..., :3].copy()
        import matplotlib.pyplot as plt

        if self._figure is None:
            plt.ion()
            self._figure = plt.figure(figsize=self.size, dpi=self.dpi)
        draw_scene(scene, self._figure, agent_names)
        self._figure.canvas.draw_idle()
        plt.pause(0.001)
        return None

    def close(self) -> None:
        if self._figure is not None and self.render_mode == "human":
            import matplotlib.pyplot as plt

            plt.close(self._figure)
        self._figure = None
