"""Shared figure conventions for coloc's PNGs, and a checker that finds what a reader would trip over.

Conventions (every figure ``coloc`` writes should follow them):

* every numeric axis is labelled with its quantity and its unit in square brackets, ``"error [m]"``
  (``label``; a count is ``[count]``, a ratio without unit ``[-]``); a categorical axis (policy
  names as tick labels) needs no unit;
* a mean is drawn with its 95 % interval (error bar or band), never alone (``t_interval``);
* a legend sits outside the data (``legend_outside``: right of the axes or below them) and names
  every line, marker and band drawn;
* a log axis has at least three plain tick labels (``plain_log_ticks``), never ``6x10^0``;
* nothing depends on wall time when a deterministic quantity (particles, messages, floats) measures
  the cost.

``figure_problems`` checks the first, fourth and the legend rule on a drawn figure and returns
what it finds in words (empty: none); the tests run it on the figures they build.
"""

from __future__ import annotations

import math
import re

import numpy as np

UNIT = re.compile(r"(\[[^\]]+\]|\([^)]*(m|s|%|count|-|m\^2|m²|dB|per [^)]*)\))")


def label(quantity: str, unit: str) -> str:
    """``"quantity [unit]"``: the one way an axis names its unit."""
    return f"{quantity} [{unit}]"


def t975(dof: int) -> float:
    """Student's t quantile 0.975 with ``dof`` degrees of freedom (nan below 1)."""
    if dof < 1:
        return float("nan")
    from scipy import stats

    return float(stats.t.ppf(0.975, dof))


def t_interval(sd: float | None, n: int) -> float:
    """Half-width of a 95 % Student-t interval of a mean of ``n`` values with sample sd ``sd`` (nan if unknown)."""
    if sd is None or n < 2 or not math.isfinite(sd):
        return float("nan")
    return t975(n - 1) * sd / math.sqrt(n)


def legend_outside(ax, where: str = "right", **kwargs):
    """The axes' legend outside its data area: ``"right"`` (upper left corner beside the axes) or ``"below"``."""
    from coloc_env.config import BadInput
    options = {"fontsize": 8, "frameon": False}
    options.update(kwargs)
    if where == "right":
        return ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, **options)
    if where == "below":
        options.setdefault("ncol", 2)
        return ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), **options)
    raise BadInput(f"where must be 'right' or 'below', got {where!r}")


def plain_log_ticks(ax, axis: str = "y", minimum: int = 3) -> None:
    """Label a log axis with plain numbers (1, 2, 5, 10, ...) on at least ``minimum`` major ticks, never "6x10^0".

    Tries the decades alone where they give at least ``minimum + 1`` ticks (a range of several decades, where
    1-2-5 ticks would crowd the axis), then the 1-2-5 ticks, then every integer multiple of the decade, then the
    decades alone; where even those give fewer than ``minimum`` inside the limits (a range under a factor of
    ~1.5), the limits are widened geometrically about their centre until they do."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    target = ax.yaxis if axis == "y" else ax.xaxis
    get, put = (ax.get_ylim, ax.set_ylim) if axis == "y" else (ax.get_xlim, ax.set_xlim)
    low, high = get()
    chosen = (1.0, 2.0, 5.0)
    if np.isfinite(low) and np.isfinite(high) and low > 0 and high > low:
        for _ in range(40):
            for subs, enough in (((1.0,), minimum + 1), ((1.0, 2.0, 5.0), minimum),
                                 (tuple(float(k) for k in range(1, 10)), minimum), ((1.0,), minimum)):
                inside = [t for t in LogLocator(base=10, subs=subs).tick_values(low, high) if low <= t <= high]
                if len(inside) >= enough:
                    chosen = subs
                    break
            else:
                centre, ratio = math.sqrt(low * high), math.sqrt(high / low) * 1.15
                low, high = centre / ratio, centre * ratio
                continue
            break
        put(low, high)
    target.set_major_locator(LogLocator(base=10, subs=chosen))
    target.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
    target.set_minor_formatter(NullFormatter())


def _number(text: str) -> bool:
    try:
        float(text.replace("\u2212", "-").replace(",", ""))
    except ValueError:
        return False
    return True


def _categorical(ax, axis) -> bool:
    """An axis whose tick labels are names (policies, methods), not numbers."""
    from matplotlib.category import StrCategoryFormatter
    from matplotlib.ticker import FixedFormatter

    if isinstance(axis.get_major_formatter(), (FixedFormatter, StrCategoryFormatter)):
        return True
    texts = _visible_tick_labels(ax, axis)
    return bool(texts) and not all(_number(t) for t in texts)


def _visible_tick_labels(ax, axis, minor: bool = False) -> list[str]:
    low, high = (ax.get_ylim() if axis is ax.yaxis else ax.get_xlim())
    low, high = min(low, high), max(low, high)
    return [t.get_text() for t, v in zip(axis.get_ticklabels(minor=minor), axis.get_ticklocs(minor=minor),
                                          strict=False)
            if t.get_text() and t.get_visible() and low <= v <= high]


def _labels_shown(axis) -> bool:
    """Whether the axis draws tick labels at all (a shared axis may draw none of its own)."""
    ticks = axis.get_major_ticks()
    return axis.get_visible() and bool(ticks) and any(t.label1.get_visible() or t.label2.get_visible()
                                                      for t in ticks)


def _data_points(ax, renderer) -> np.ndarray:
    """Display coordinates of what ``ax`` draws as data: line vertices (densified), markers, band outlines."""
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D

    points = []
    for artist in ax.get_children():
        if not artist.get_visible():
            continue
        if isinstance(artist, Line2D):
            xy = np.asarray(artist.get_xydata(), float)
            if xy.ndim != 2 or not len(xy):
                continue
            display = artist.get_transform().transform(xy)
            if len(display) > 1 and artist.get_linestyle() not in ("None", "", " "):
                t = np.linspace(0.0, 1.0, 12)[:, None, None]
                display = (display[:-1][None] * (1 - t) + display[1:][None] * t).reshape(-1, 2)
            points.append(display)
        elif isinstance(artist, Collection):
            offsets = artist.get_offsets()
            if offsets is not None and len(offsets) and artist.get_offset_transform() is not None:
                points.append(artist.get_offset_transform().transform(np.asarray(offsets, float)))
            for path in artist.get_paths():
                verts = path.vertices
                if len(verts) and len(verts) < 2000:
                    points.append(artist.get_transform().transform(verts))
    if not points:
        return np.zeros((0, 2))
    stacked = np.concatenate(points)
    return stacked[np.all(np.isfinite(stacked), axis=1)]


def figure_problems(fig, units: bool = True) -> list[str]:
    """What breaks the conventions above on the drawn figure ``fig``, in words (empty: nothing found).

    Checks every axes that shows its axis (not insets without ticks): each numeric axis has a label with a
    unit in brackets or parentheses (``units``); a log axis shows at least three tick labels; no legend
    (of an axes or of the figure) covers a data point, line or band outline of any axes."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    problems = []
    for index, ax in enumerate(fig.axes):
        if not ax.get_visible() or not ax.axison:
            continue
        name = ax.get_title() or f"axes {index}"
        for axis, which in ((ax.xaxis, "x"), (ax.yaxis, "y")):
            if not _labels_shown(axis):
                continue  # a shared axis without its own labels, or an axis turned off
            scale = ax.get_xscale() if which == "x" else ax.get_yscale()
            shown = len(_visible_tick_labels(ax, axis)) + len(_visible_tick_labels(ax, axis, minor=True))
            if scale == "log" and shown < 3:
                problems.append(f"{name}: log {which} axis with {shown} tick labels")
            if scale == "log" and any("times" in t or "^" in t for t in
                                      _visible_tick_labels(ax, axis) + _visible_tick_labels(ax, axis, minor=True)):
                problems.append(f"{name}: log {which} axis labelled in powers of ten, not plain numbers")
            if units and not _categorical(ax, axis):
                text = axis.get_label().get_text()
                if not text:
                    problems.append(f"{name}: {which} axis without a label")
                elif not UNIT.search(text):
                    problems.append(f"{name}: {which} label {text!r} names no unit")
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None] + list(fig.legends)
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for index, ax in enumerate(fig.axes):
            points = _data_points(ax, renderer)
            clip = ax.get_window_extent(renderer)
            inside_axes = (points[:, 0] >= clip.x0) & (points[:, 0] <= clip.x1) & \
                (points[:, 1] >= clip.y0) & (points[:, 1] <= clip.y1)
            covered = inside_axes & (points[:, 0] > box.x0) & (points[:, 0] < box.x1) & \
                (points[:, 1] > box.y0) & (points[:, 1] < box.y1)
            if covered.any():
                name = ax.get_title() or f"axes {index}"
                problems.append(f"{name}: the legend covers {int(covered.sum())} data points")
    return problems
