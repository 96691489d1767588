"""Shared look: the paper's colours, colour maps and matplotlib settings.

Zone colours (proximal blue, mid green, distal red), raw/smoothed and excitation colours are those of the
published figures (reference pipeline doc section 5), so figures can be compared side by side.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np

ZONE_COLORS = {"proximal": "#2166ac", "mid": "#4dac26", "distal": "#d7191c", "root": "#777777"}
RAW_COLOR = "#e66101"
SMOOTHED_COLOR = "#4393c3"
EXCITATION_COLOR = "#762a83"
PREDICTED_COLOR = "#f0f0f0"
MISSING_COLOR = "#b4b4b4"

#: Colour map of kappa (low = stiff = blue, high = compliant = red), as the published overlays.
KAPPA_CMAP = "RdYlBu_r"
#: Colour map of U_e (low = certain = green, high = uncertain = red), as the published overlays.
UNCERTAINTY_CMAP = "RdYlGn_r"
#: Diverging colour map of residuals, centred at 0.
RESIDUAL_CMAP = "RdBu_r"

#: matplotlib rcParams for every figure (two-column paper width, 8-pt text, no top/right spines).
RC = {
    "font.size": 8, "axes.titlesize": 9, "axes.labelsize": 8, "xtick.labelsize": 7, "ytick.labelsize": 7,
    "legend.fontsize": 7, "legend.frameon": False, "axes.spines.top": False, "axes.spines.right": False,
    "axes.titleweight": "bold", "axes.titlelocation": "left", "figure.dpi": 100, "savefig.dpi": 150,
    "savefig.bbox": "tight", "savefig.pad_inches": 0.05, "lines.linewidth": 1.0, "axes.grid": True,
    "grid.alpha": 0.25, "grid.linewidth": 0.5,
    # titles sit at the top of their axes (no figure here has tick labels above an axes): matplotlib's
    # automatic placement measured every tick label of every axes at each draw, a sixth of the figures' time
    "axes.titley": 1.0,
}
FIG_WIDTH_IN = 7.16  # two-column figure width in inches


def hex_to_rgb(color: str) -> tuple[int, int, int]:
    """'#rrggbb' -> (r, g, b) 0..255."""
    c = color.lstrip("#")
    return tuple(int(c[i:i + 2], 16) for i in (0, 2, 4))


def zone_rgb(zones) -> np.ndarray:
    """(n, 3) uint8 colours of zone names."""
    return np.array([hex_to_rgb(ZONE_COLORS.get(str(z), "#777777")) for z in zones], dtype=np.uint8).reshape(-1, 3)


def cmap_rgb(values: np.ndarray, cmap: str, vmin: float, vmax: float, nan_rgb=(180, 180, 180)) -> np.ndarray:
    """(..., 3) uint8 colours of ``values`` through a matplotlib colour map on [vmin, vmax]; NaN -> grey."""
    from matplotlib import colormaps
    v = np.asarray(values, dtype=float)
    span = vmax - vmin if vmax > vmin else 1.0
    s = np.clip((v - vmin) / span, 0.0, 1.0)
    rgb = (colormaps[cmap](np.nan_to_num(s))[..., :3] * 255).round().astype(np.uint8)
    rgb[~np.isfinite(v)] = nan_rgb
    return rgb


def robust_abs_max(values: np.ndarray, q: float = 99.0) -> float:
    """q-th percentile of |values| over finite entries (colour limit that one outlier cannot stretch)."""
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    m = float(np.percentile(v, q))
    return m if m > 0 else float(v.max() or 1.0)


class Figures:
    """The three pyplot calls the figure modules make (``subplots``, ``figure``, ``get_cmap``), on plain
    :class:`matplotlib.figure.Figure` objects: no pyplot import (~0.2 s of every ``rce analyze``'s figure
    worker) and no figure registry to leak into; ``savefig`` renders them with Agg."""

    @staticmethod
    def figure(figsize=None, **kwargs):
        from matplotlib.figure import Figure
        return Figure(figsize=figsize, **kwargs)

    @staticmethod
    def subplots(nrows: int = 1, ncols: int = 1, *, figsize=None, constrained_layout=None, **kwargs):
        from matplotlib.figure import Figure
        fig = Figure(figsize=figsize, constrained_layout=constrained_layout)
        return fig, fig.subplots(nrows, ncols, **kwargs)

    @staticmethod
    def get_cmap(name: str):
        import matplotlib
        return matplotlib.colormaps[name]


@contextmanager
def mpl_style():
    """Context: matplotlib with the shared rc settings :data:`RC`; yields :class:`Figures` (pyplot's
    ``subplots`` / ``figure`` / ``get_cmap`` without pyplot). Figures are saved (Agg) by :func:`save_png`."""
    import matplotlib
    with matplotlib.rc_context(RC):
        yield Figures


def fixed_margins(fig, left: float = 0.6, right: float = 0.12, top: float = 0.3, bottom: float = 0.45,
                  wspace: float = 0.0, hspace: float = 0.0, ncols: int = 1, nrows: int = 1) -> None:
    """Place ``fig``'s subplots with fixed margins, in inches: ``left`` .. ``bottom`` around the grid,
    ``wspace`` / ``hspace`` between its ``ncols`` columns / ``nrows`` rows.

    The analysis figures use this instead of constrained layout: their text sizes are fixed (:data:`RC`),
    so margins in inches fit them, and measuring every label's extent before drawing was a third of each
    figure's time (``rce analyze`` waits for the figures)."""
    W, H = fig.get_size_inches()
    aw = (W - left - right - (ncols - 1) * wspace) / ncols
    ah = (H - top - bottom - (nrows - 1) * hspace) / nrows
    fig.subplots_adjust(left=left / W, right=1 - right / W, bottom=bottom / H, top=1 - top / H,
                        wspace=wspace / aw, hspace=hspace / ah)


def save_png(fig, path: Path) -> Path:
    """Save ``fig`` to ``path`` with the shared output settings and close it; returns ``path``."""
    import sys
    # savefig runs outside the rc_context the figure was built in, so pass the output settings here. Every
    # figure is laid out (constrained layout or :func:`fixed_margins`) to keep its artists inside the canvas:
    # a "tight" bounding box would only trim the margin, at the price of drawing the whole figure twice.
    # zlib level 1: a third of the PNG encoding time of the default 6, the same pixels, files ~1.3x larger
    fig.savefig(path, dpi=RC["savefig.dpi"], bbox_inches=None, pil_kwargs={"compress_level": 1})
    if "matplotlib.pyplot" in sys.modules:  # a figure made through pyplot (callers' own): unregister it
        sys.modules["matplotlib.pyplot"].close(fig)
    return path
