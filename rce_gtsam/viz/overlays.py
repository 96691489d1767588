"""kappa and U_e drawn on the first video frame (or on a neutral background when there is no video).

Each segment of the first-frame skeleton (smoothed positions at frame 0, pixels) is drawn as a thick
line coloured by its value: kappa (blue = stiff, red = compliant; log colour scale, since kappa is a
ratio with geometric mean 1) or U_e = CI width / kappa (green = certain, red = uncertain). The root
edge has no bend, hence no value, and is drawn grey. A segment whose kappa is not ``ok``
(:mod:`rce_gtsam.quality`) is hatched with a black-and-white dashed line down its middle and labelled with its first
flag (``poor_fit``, ``uninformative``, ...): its colour is a value not to be trusted. The view is cropped to
the skeleton plus a margin.

Files: ``kappa_overlay.png`` and ``uncertainty_overlay.png`` (PNG, 150 dpi).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .style import KAPPA_CMAP, MISSING_COLOR, UNCERTAINTY_CMAP, fixed_margins
from .style import mpl_style as _style
from .style import save_png as _save

BACKGROUND_RGB = (236, 236, 232)  # neutral light grey when there is no video frame
MARGIN_PX = 40  # crop margin around the skeleton, pixels of the original image


def first_frame_skeleton(result) -> tuple[np.ndarray, list[tuple[int, int]], np.ndarray]:
    """(N, 2) smoothed node positions at frame 0, the graph edges, and each node's row."""
    xy = result.smoothed.tracks.xy[:, 0]
    return xy, list(result.graph.edges), result.tracks.node_ids


def fig_overlay(result, values: dict, label: str, cmap: str, first_frame: np.ndarray | None = None,
                log: bool = False, title: str = "", flags: dict | None = None, scale_with=()):
    """Draw the first-frame skeleton with each edge coloured by ``values[edge]`` (NaN/missing = grey);
    ``flags``: {edge: quality string} of the segments whose kappa is not ``ok``, hatched and labelled;
    ``scale_with``: more values the colour scale must span (with ``log``: another κ of the same segments, so
    that two overlays share one scale)."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import LogNorm, Normalize
    xy, edges, ids = first_frame_skeleton(result)
    row = {int(n): i for i, n in enumerate(ids)}
    segs = np.array([[xy[row[p]], xy[row[c]]] for p, c in edges])
    v = np.array([values.get(e, np.nan) for e in edges], dtype=float)
    ok = np.isfinite(v) & ((v > 0) if log else True)
    if first_frame is not None:
        H, W = first_frame.shape[:2]
        bg = first_frame
    else:
        W = int(max(640, np.nanmax(xy[:, 0]) + MARGIN_PX))
        H = int(max(480, np.nanmax(xy[:, 1]) + MARGIN_PX))
        bg = np.broadcast_to(np.array(BACKGROUND_RGB, np.uint8), (H, W, 3))
    x0, x1 = max(0, np.nanmin(xy[:, 0]) - MARGIN_PX), min(W, np.nanmax(xy[:, 0]) + MARGIN_PX)
    y0, y1 = max(0, np.nanmin(xy[:, 1]) - MARGIN_PX), min(H, np.nanmax(xy[:, 1]) + MARGIN_PX)
    if ok.any():
        lo, hi = float(v[ok].min()), float(v[ok].max())
        extra = np.asarray(list(scale_with), dtype=float)
        extra = extra[np.isfinite(extra) & (extra > 0)] if log else extra[np.isfinite(extra)]
        if extra.size:
            lo, hi = min(lo, float(extra.min())), max(hi, float(extra.max()))
        if log:
            m = max(hi, 1.0 / lo)  # symmetric around kappa = 1 on a log scale
            norm = LogNorm(1.0 / m, m) if m > 1 else LogNorm(0.5, 2.0)
        else:
            # cap the scale at 4x the median so one unstable edge does not wash out the others
            cap = 4.0 * float(np.median(v[ok]))
            norm = Normalize(0.0, min(hi, cap) if min(hi, cap) > 0 else 1.0)
    else:
        norm = Normalize(0, 1)
    with _style() as plt:
        aspect = (x1 - x0) / max(y1 - y0, 1)
        h = 4.2
        fig, ax = plt.subplots(figsize=(min(7.16, h * aspect + 1.4), h))
        fixed_margins(fig, left=0.5, right=0.6, top=0.28 + 0.16 * title.count("\n"), bottom=0.4)
        # only the cropped part of the photo, faded toward white once here (two full-frame images, one of
        # them a float RGBA veil, were most of an overlay's drawing time)
        r0, r1 = int(max(0, np.floor(y0))), int(min(H, np.ceil(y1) + 1))
        c0, c1 = int(max(0, np.floor(x0))), int(min(W, np.ceil(x1) + 1))
        faded = (0.75 * np.asarray(bg[r0:r1, c0:c1], dtype=np.float32) + 0.25 * 255).astype(np.uint8)
        ax.imshow(faded, extent=(c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5), interpolation="bilinear")
        # a dark casing under every segment keeps pale mid-scale colours visible on a light background
        ax.add_collection(LineCollection(segs, colors="0.15", linewidths=8.5, capstyle="round", zorder=1.5))
        ax.add_collection(LineCollection(segs[~ok], colors=MISSING_COLOR, linewidths=6, capstyle="round",
                                         zorder=2))
        lc = LineCollection(segs[ok], cmap=cmap, norm=norm, linewidths=6, capstyle="round", zorder=3)
        lc.set_array(v[ok])
        ax.add_collection(lc)
        flag_texts = _mark_flagged(ax, segs, edges, flags or {})
        ax.scatter(xy[:, 0], xy[:, 1], s=9, c="white", edgecolors="k", linewidths=0.5, zorder=5)
        r = row[result.graph.root]
        ax.scatter([xy[r, 0]], [xy[r, 1]], s=40, facecolors="none", edgecolors="#1a9850", linewidths=1.5, zorder=6)
        node_texts = _label_nodes(ax, xy, ids, edges, row)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_aspect("equal")
        ax.grid(False)
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
        ax.set_title(title)
        extend = "max" if (not log and ok.any() and v[ok].max() > norm.vmax) else "neither"
        cb = fig.colorbar(lc, ax=ax, shrink=0.85, pad=0.02, extend=extend)
        cb.set_label(label)
        _flag_legend(ax, len(flag_texts), _drop_overlapping(fig, node_texts, flag_texts))
        if log:
            from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
            ticks = [t * 10.0 ** k for k in range(-3, 3) for t in (1, 2, 5) if norm.vmin <= t * 10.0 ** k <= norm.vmax]
            cb.ax.yaxis.set_major_locator(FixedLocator(ticks))
            cb.ax.yaxis.set_minor_locator(NullLocator())
            cb.ax.yaxis.set_major_formatter(FuncFormatter(lambda t, _: f"{t:g}"))
    return fig


def _mark_flagged(ax, segs: np.ndarray, edges, flags: dict) -> list:
    """A dashed line down the middle of each flagged segment and its first flag beside it (on the side
    opposite the node labels); returns those labels (:func:`_drop_overlapping` thins them where they crowd)."""
    import matplotlib.patheffects as pe
    from matplotlib.collections import LineCollection
    idx = [i for i, e in enumerate(edges) if flags.get(e, "ok") != "ok"]
    if not idx:
        return []
    # black dashes with a white rim read on every colour of the scale, pale or dark
    dashes = LineCollection(segs[idx], colors="0.05", linewidths=1.4, linestyles=(0, (2.0, 1.6)), zorder=4,
                            path_effects=[pe.withStroke(linewidth=2.6, foreground="white")])
    dashes.set_gid("flagged")
    ax.add_collection(dashes)
    texts = []
    for i in idx:
        (xa, ya), (xb, yb) = segs[i]
        d = np.array([xb - xa, yb - ya])
        n = np.array([d[1], -d[0]]) / (np.linalg.norm(d) or 1.0)  # the other side from _label_nodes' offset
        texts.append(ax.annotate(flags[edges[i]].split("+")[0], ((xa + xb) / 2, (ya + yb) / 2),
                                 xytext=(14 * n[0], -14 * n[1]), textcoords="offset points", ha="center",
                                 va="center", fontsize=5, color="0.35", style="italic", zorder=7,
                                 path_effects=[pe.withStroke(linewidth=1.8, foreground="white")]))
    return texts


def _drop_overlapping(fig, keep: list, candidates: list) -> int:
    """Remove each of ``candidates`` (text artists, in order) whose box on the figure overlaps a text of ``keep``
    or a candidate kept before it; returns how many were removed. Where segments are short and mostly flagged
    their labels would print over each other and over the node ids ("poor_fitpoor_fit"); the dashes still mark
    every flagged segment, and the quality column names each flag."""
    if not candidates:
        return 0
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    # the boxes as the saved figure lays them out, without drawing it: an Agg renderer measures the texts once
    # the axes have their final aspect (a full draw here cost ~0.1 s per overlay)
    renderer = FigureCanvasAgg(fig).get_renderer()
    for ax in fig.axes:
        ax.apply_aspect()
    boxes = [t.get_window_extent(renderer) for t in keep]
    removed = 0
    for t in candidates:
        box = t.get_window_extent(renderer)
        if any(box.overlaps(b) for b in boxes):
            t.remove()
            removed += 1
        else:
            boxes.append(box)
    return removed


def _flag_legend(ax, n_flagged: int, n_unlabelled: int) -> None:
    """The legend entry saying what the dashes mean (none without flagged segments)."""
    if not n_flagged:
        return
    import matplotlib.patheffects as pe
    from matplotlib.lines import Line2D
    where = "; labelled where there is room" if n_unlabelled else ""
    ax.legend(handles=[Line2D([], [], color="0.05", lw=1.4, ls=(0, (2.0, 1.6)),
                              path_effects=[pe.withStroke(linewidth=2.6, foreground="white")])],
              labels=[f"flagged: κ not ok ({n_flagged} segments; quality column{where})"], loc="lower left",
              fontsize=6, frameon=True, framealpha=0.85)


def _label_nodes(ax, xy: np.ndarray, ids, edges, row) -> list:
    """Each node's id beside it (the ids the tables and the diagnosis name), 12 pt off the branch across
    the node's own segments, in dark text with a white halo that reads on any photo; returns the labels."""
    import matplotlib.patheffects as pe
    tangent = np.zeros_like(xy)
    for p, c in edges:  # a node's direction: the sum of its segments' unit vectors (root -> tip)
        d = xy[row[c]] - xy[row[p]]
        d = d / (np.linalg.norm(d) or 1.0)
        tangent[row[p]] += d
        tangent[row[c]] += d
    texts = []
    for (x, y), t, nid in zip(xy, tangent, ids):
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        n = np.array([-t[1], t[0]]) / (np.linalg.norm(t) or 1.0)  # perpendicular, image coordinates (y down)
        if not n.any():
            n = np.array([1.0, 0.0])
        texts.append(ax.annotate(str(int(nid)), (x, y), xytext=(12 * n[0], -12 * n[1]),
                                 textcoords="offset points", ha="center", va="center", fontsize=6, color="0.1",
                                 zorder=7, path_effects=[pe.withStroke(linewidth=2, foreground="white")]))
    return texts


#: Overlay files, and those that need kappa's confidence intervals (both: the flags they mark include the
#: interval's, wide_ci and uninformative).
OVERLAY_FILES = ("kappa_overlay.png", "uncertainty_overlay.png")
CI_OVERLAYS = ("kappa_overlay.png", "uncertainty_overlay.png")
#: Drawn besides, when the diagnosis named an effect and its model's κ was fitted (``result.kappa_choice``):
#: that κ, the one to report, on the same colour scale as ``kappa_overlay.png``'s rank-1 κ.
REPORTED_OVERLAY = "kappa_to_report_overlay.png"


def write_overlays(result, out_dir: str | Path, first_frame: np.ndarray | None = None,
                   names=None) -> dict[str, Path]:
    """Write ``kappa_overlay.png`` (the rank-1 κ), ``uncertainty_overlay.png`` and, when ``result`` carries the κ
    of a model with a named effect (``kappa_choice.fitted``, as ``rce run`` and ``rce batch`` fit it),
    :data:`REPORTED_OVERLAY` into ``out_dir``.

    ``first_frame``: (H, W, 3) uint8 RGB first video frame, or None for a neutral background.
    ``names``: only these files (default: all that apply). Usable as an ``extra_writer`` through
    ``lambda r, d: write_overlays(r, d, frame)``."""
    from ..quality import assess_quality, assess_reported_quality
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rank1 = assess_quality(result)
    flags = {e: q.quality for e, q in rank1.items() if not q.ok}
    kappa = result.kappa
    U = result.uncertainty
    unc = {} if U is None else {e: float(u) for e, u in zip(result.response.edges, U)}
    where = "first video frame" if first_frame is not None else "first-frame skeleton"
    choice = getattr(result, "kappa_choice", None)
    named = choice is not None and choice.fitted
    makers = {
        "kappa_overlay.png": lambda: fig_overlay(
            result, kappa, "relative compliance κ (log scale)", KAPPA_CMAP, first_frame, log=True, flags=flags,
            title=(f"rank-1 κ, not the κ to report ({choice.column} is),\non the {where}" if named
                   else f"κ per segment on the {where}"),
            scale_with=choice.kappa if named else ()),
        "uncertainty_overlay.png": lambda: fig_overlay(result, unc, "U_e = CI width / κ", UNCERTAINTY_CMAP,
                                                       first_frame, title=f"Uncertainty U_e on the {where}",
                                                       flags=flags),
    }
    if named:
        def reported():
            quality = assess_reported_quality(result, rank1)
            values = {tuple(e): float(k) for e, k in zip(choice.edges, choice.kappa)}
            return fig_overlay(result, values, "relative compliance κ (log scale)", KAPPA_CMAP, first_frame,
                               log=True, flags={e: q.quality for e, q in quality.items() if not q.ok},
                               title=f"κ to report: {choice.column}\n(the model with {choice.effect}) on the {where}",
                               scale_with=list(kappa.values()))
        makers[REPORTED_OVERLAY] = reported
    return {name: _save(make(), out / name) for name, make in makers.items() if names is None or name in names}
