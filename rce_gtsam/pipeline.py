"""The analysis pipeline: tracks -> smoothed tracks -> bends -> response matrix -> rank-1 compliance
(optionally extended by physical effect terms, ``analyze(..., effects=("delay",))``).

Every stage is a plain function of typed values; :func:`analyze` chains them and times each one.
Which numbers and switches each stage uses comes from a :class:`~rce_gtsam.presets.Preset`.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from .bending.angles import BendingResult, compute_bending
from .model.compliance import Rank1Fit, fit_rank1, frame_precisions
from .model.uncertainty import BootstrapCI, bootstrap_kappa
from .extended_fit import ExtendedBootstrapInfo, ExtendedFit, bootstrap_extended, fit_extended
from .bending.geometry import Geometry, compute_geometry, edge_lengths
from .graph import BranchGraph, load_graph
from .model import ResponseModel
from .model.time_split import TimeSplitCheck, time_split_check, widen
from .smoothing.marginals import single_threaded_blas
from .presets import Preset, get_preset
from .smoothing.smoother import SmoothedTracks, smooth_tracks
from .tracks import Tracks, dropped_edges, load_tracks, lost_nodes  # noqa: F401 (re-exported)


@dataclass(frozen=True, eq=False)
class Response:
    """The data the rank-1 model is fitted to.

    Y: (E, T) bending response in degrees (|delta| for the paper's ``abs`` response, signed delta
       otherwise); NaN where the bend is missing or an outlier.
    variance: (E, T) propagated angle variance in deg^2, or None.
    covariance: (T, E, E) propagated covariance between the rows at each frame in deg^2 (NaN where an
       entry is missing or an outlier), or None.
    edges: the downstream edge (joint, child) of each row; rows are ordered by root distance, then
       joint, then child.
    bend_rows: index of each row in ``BendingResult.bends``.
    root_distance_px: (E,) root distance of each edge's child (pixels); root_distance: (E,) the same
       divided by the branch's largest root distance (0..1).
    frames: (T,) video frame index of each column (frames where any bend has a finite angle).
    """

    Y: np.ndarray
    variance: np.ndarray | None
    edges: list[tuple[int, int]]
    bend_rows: np.ndarray
    root_distance_px: np.ndarray
    root_distance: np.ndarray
    frames: np.ndarray
    covariance: np.ndarray | None = None

    def _inverse_variance(self) -> tuple[np.ndarray, float]:
        """(E, T) 1 / variance (0 where the entry or its variance is unusable) and its mean over the
        positive entries (1.0 if none): the normalisation :attr:`weights` and :attr:`precision` share."""
        with np.errstate(divide="ignore", invalid="ignore"):
            w = 1.0 / self.variance
        w = np.where(np.isfinite(w) & np.isfinite(self.Y), w, 0.0)
        pos = w > 0
        return w, float(w[pos].mean()) if pos.any() else 1.0

    @property
    def edge_labels(self) -> list[str]:
        """Each row's ``"joint->child"`` label (what reports, ``diagnosis.json`` and
        :func:`~rce_gtsam.model.row_sets.edge_nodes_from_labels` read)."""
        return [f"{j}->{c}" for j, c in self.edges]

    @property
    def weights(self) -> np.ndarray | None:
        """(E, T) inverse-variance weights (1/deg^2) normalised to mean 1 over finite entries, or None."""
        if self.variance is None:
            return None
        w, scale = self._inverse_variance()
        return w / scale

    @property
    def precision(self) -> np.ndarray | None:
        """(T, E, E) per-frame precision: the inverse of the covariance of the entries observed at frame t
        (zero rows and columns elsewhere), scaled like :attr:`weights` (without correlations its diagonal
        would equal the weights), or None without covariances. See
        :func:`~rce_gtsam.model.compliance.frame_precisions`.
        """
        if self.covariance is None or self.variance is None:
            return None
        return frame_precisions(self.covariance, np.isfinite(self.Y)) / self._inverse_variance()[1]


@dataclass(frozen=True, eq=False)
class SmoothingMetrics:
    """How much smoothing changed the bending and edge-length statistics (reference doc §2.11).

    bend_rms_raw_deg / bend_rms_smoothed_deg: (B,) filtered RMS of delta over inlier frames per bend,
    on the presmoothed ("raw") and the smoothed tracks; edge_cv_raw / edge_cv_smoothed: (edges,)
    coefficient of variation of each edge's length over its observed frames. Reductions are
    1 - mean(smoothed) / mean(raw), in percent.
    """

    bend_rms_raw_deg: np.ndarray
    bend_rms_smoothed_deg: np.ndarray
    edge_cv_raw: np.ndarray
    edge_cv_smoothed: np.ndarray

    @staticmethod
    def _reduction(raw, smoothed) -> float:
        with np.errstate(divide="ignore", invalid="ignore"):  # static tracks: both means are 0
            return float(100.0 * (1.0 - np.nanmean(smoothed) / np.nanmean(raw)))

    def as_dict(self) -> dict:
        with warnings.catch_warnings():  # every bend an outlier: NaN means, said by the quality verdicts
            warnings.simplefilter("ignore", RuntimeWarning)
            return {
                "mean_bend_rms_raw_deg": float(np.nanmean(self.bend_rms_raw_deg)),
                "mean_bend_rms_smoothed_deg": float(np.nanmean(self.bend_rms_smoothed_deg)),
                "bend_rms_reduction_pct": self._reduction(self.bend_rms_raw_deg, self.bend_rms_smoothed_deg),
                "mean_edge_length_cv_raw": float(np.nanmean(self.edge_cv_raw)),
                "mean_edge_length_cv_smoothed": float(np.nanmean(self.edge_cv_smoothed)),
                "edge_length_cv_reduction_pct": self._reduction(self.edge_cv_raw, self.edge_cv_smoothed),
                "n_bends": int(self.bend_rms_raw_deg.size),
                "n_edges": int(self.edge_cv_raw.size),
            }


def observed_positions(smoothed: SmoothedTracks) -> np.ndarray:
    """(N, F, 2) smoothed positions at the input's observed frames only, NaN elsewhere.

    Missing frames are never interpolated into the analysis: the smoother estimates them (and they
    carry its covariance), but bends and lengths only use frames a tracker actually saw.
    """
    xy = smoothed.tracks.xy.copy()
    xy[~smoothed.observed] = np.nan
    return xy


def filtered_rms(bending: BendingResult) -> np.ndarray:
    """(B,) sqrt(mean delta^2) over each bend's inlier frames, degrees."""
    d2 = np.where(bending.inlier, bending.delta_deg**2, np.nan)
    with warnings.catch_warnings():  # a bend with no inlier frame gives NaN ("mean of empty slice")
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.sqrt(np.nanmean(d2, axis=1))


def length_cv(xy: np.ndarray, node_ids, graph: BranchGraph) -> np.ndarray:
    """(edges,) population std / mean of each edge's length over its common frames."""
    row = {int(n): i for i, n in enumerate(node_ids)}
    out = []
    for e in graph.edges:
        L = edge_lengths(xy, row, e)
        L = L[np.isfinite(L)]
        out.append(float(L.std() / L.mean()) if L.size and L.mean() > 0 else float("nan"))
    return np.array(out)


def _smoother_input(tracks: Tracks, lost) -> Tracks:
    """``tracks`` with each lost node held still at its observed position(s) in every frame: the smoother
    needs two observations per node, and a node that stands still beside its neighbours pulls on nothing
    (no edge factor is strained by it). Only its really observed frames are used downstream
    (``SmoothedTracks.observed`` is the input's mask), and every bend through it is dropped."""
    if not lost:
        return tracks
    xy = tracks.xy.copy()
    sigma = None if tracks.sigma_px is None else tracks.sigma_px.copy()
    obs = tracks.observed
    for n in lost:
        i = tracks.index(n)
        if not obs[i].any():
            continue  # never observed: nothing to hold it at (the smoother says so, naming the node)
        xy[i] = np.nanmean(xy[i][obs[i]], axis=0)
        if sigma is not None:
            sigma[i] = np.nanmean(sigma[i][obs[i]])
    return Tracks(node_ids=tracks.node_ids, xy=xy, sigma_px=sigma, source=tracks.source,
                  lost_nodes=tracks.lost_nodes)


def build_response(bending: BendingResult, geometry: Geometry, preset: Preset, skip_nodes=()) -> Response:
    """Arrange the bends as the (edges x frames) matrix the compliance model fits; bends through
    ``skip_nodes`` (lost nodes) are left out."""
    skip = set(int(n) for n in skip_nodes)
    keep = [k for k, b in enumerate(bending.bends) if not skip & set(b.nodes)]
    if not keep:
        from .errors import InputError
        raise InputError("tracks", f"every bend runs through a lost node ({', '.join(map(str, sorted(skip)))}: observed in "
                         "fewer than 2 frames); nothing usable is left to fit")
    keys = {k: (geometry.root_distance_px[bending.bends[k].child], bending.bends[k].joint, bending.bends[k].child)
            for k in keep}
    order = np.array(sorted(keep, key=lambda k: keys[k]), dtype=int)
    frames = np.flatnonzero(np.isfinite(bending.delta_deg).any(axis=0))
    delta = bending.delta_deg[order][:, frames]
    inlier = bending.inlier[order][:, frames]
    Y = np.abs(delta) if preset.compliance.response == "abs" else delta.copy()
    Y[~inlier] = np.nan
    variance = covariance = None
    if bending.variance_deg2 is not None:
        variance = bending.variance_deg2[order][:, frames].copy()
        variance[~inlier] = np.nan
    if bending.covariance_deg2 is not None:
        covariance = bending.covariance_deg2[np.ix_(frames, order, order)]  # one (T, E, E) copy
        out = ~inlier.T  # (T, E)
        covariance[out[:, :, None] | out[:, None, :]] = np.nan
    rd = np.array([geometry.root_distance_px[bending.bends[k].child] for k in order])
    top = max(geometry.root_distance_px.values())
    return Response(Y=Y, variance=variance, covariance=covariance, edges=[bending.bends[k].edge for k in order], bend_rows=order,
                    root_distance_px=rd, root_distance=rd / top if top > 0 else np.zeros_like(rd),
                    frames=frames)


#: The steps :func:`analyze` reports to its ``progress`` callback, in order.
ANALYSIS_STEPS = ("load", "smooth", "bending", "fit", "bootstrap")


@dataclass(frozen=True, eq=False)
class AnalysisResult:
    """Everything one analysis computed; :mod:`rce_gtsam.results` turns it into tables and files."""

    graph: BranchGraph
    tracks: Tracks
    preset: Preset
    smoothed: SmoothedTracks
    geometry: Geometry
    bending: BendingResult
    raw_bending: BendingResult
    response: Response
    fit: Rank1Fit | ExtendedFit
    ci: BootstrapCI | None
    smoothing: SmoothingMetrics
    timings_s: dict[str, float] = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)
    effects: tuple[str, ...] = ()
    effects_bootstrap: ExtendedBootstrapInfo | None = None
    time_split: TimeSplitCheck | None = None  # batch-means check that widened the CIs (None: off)
    #: which kappa to report after a diagnosis (rce_gtsam.kappa_report; None: no diagnosis ran)
    kappa_choice: object | None = None

    @property
    def kappa(self) -> dict[tuple[int, int], float]:
        """Relative compliance per edge (joint, child)."""
        return {e: float(k) for e, k in zip(self.response.edges, self.fit.kappa)}

    @property
    def uncertainty(self) -> np.ndarray | None:
        """(E,) U_e = (CI high - CI low) / kappa_e, or None without a bootstrap."""
        if self.ci is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.fit.kappa > 1e-9, (self.ci.high - self.ci.low) / self.fit.kappa, np.nan)

    @cached_property
    def kappa_floor(self):
        """What limits kappa on this recording: the accuracy the tracker's node error (estimated from the rank-1
        residuals) allows on this branch and this bending (:class:`~rce_gtsam.kappa_floor.KappaFloor`,
        computed once; seed: the preset's). None for an extended model's fit, or where it cannot be computed."""
        if self.effects:
            return None
        from .kappa_floor import kappa_floor_of
        return kappa_floor_of(self, seed=self.preset.compliance.seed)

    def summary(self):
        from .results import compliance_summary
        return compliance_summary(self)

    def effects_report(self) -> dict | None:
        """The ``effects`` section of report.json (None without effects): the extended model, its effect
        parameters (value, stderr, unit), fit statistics and how the bootstrap treated the effects."""
        if not self.effects:
            return None
        out = self.fit.report_dict()
        out["bootstrap"] = None if self.effects_bootstrap is None else self.effects_bootstrap.as_dict()
        return out

    def write(self, out_dir: str | Path, extra_writers=(), **kwargs) -> dict[str, Path]:
        from .results import write_outputs
        return write_outputs(self, out_dir, extra_writers=extra_writers, **kwargs)


def analyze(tracks: Tracks | str | Path, graph: BranchGraph | str | Path, preset: str | Preset = "default",
            seed: int | None = None, n_boot: int | None = None, effects: tuple[str, ...] | str = (),
            progress=None, before_bootstrap=None, inputs: dict[str, str] | None = None) -> AnalysisResult:
    """Run the whole analysis on saved tracks.

    ``tracks`` and ``graph`` may be objects or file paths. ``seed`` and ``n_boot`` override the preset's
    bootstrap seed and resample count. ``effects``: names of physical effect terms (``delay``,
    ``dynamics``, ``second_mode``, ``offset``, ``nonlinear``; a tuple or ``"a,b"``) to add to the rank-1
    model; kappa and its bootstrap CIs then come from the extended model
    (:mod:`rce_gtsam.extended_fit`). An unknown name is an :class:`~rce_gtsam.errors.InputError`.
    ``progress``: optional callable ``progress(step)`` called as each of :data:`ANALYSIS_STEPS` starts
    (the CLI's progress bar). ``before_bootstrap``: optional callable given the result without CIs
    (``ci=None``) just before the bootstrap starts (the CLI draws the figures that need no CI meanwhile).
    ``inputs``: the files ``tracks`` and ``graph`` were read from when they are passed as objects
    (``{"graph": path, "tracks": path}``, recorded in report.json; paths passed directly are recorded).
    """
    step = progress or (lambda _name: None)
    from .diagnosis.io import parse_effect_names
    effects = parse_effect_names(effects, source="effects") or ()
    if effects:  # the effects (and scipy.signal, scipy.stats with them: 0.9 s) only when some are asked for
        from .effects import make
        needs_more = [n for n in effects if not make(n).available]  # reads more than the bends (out_of_plane)
    else:
        needs_more = []
    if needs_more:
        from .errors import InputError
        raise InputError("effects", f"{', '.join(needs_more)} reads more of the recording than the bend angles and "
                                    "is not fitted by name; rce diagnose and rce run try it with the recording's data")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    step("load")
    inputs = dict(inputs or {})
    if not isinstance(graph, BranchGraph):
        inputs["graph"] = str(graph)
        graph = load_graph(graph)
    if not isinstance(tracks, Tracks):
        inputs["tracks"] = str(tracks)
        tracks = load_tracks(tracks, graph)
    preset = get_preset(preset)
    overrides = {}
    if seed is not None:
        overrides["seed"] = int(seed)
    if n_boot is not None:
        overrides["n_boot"] = int(n_boot)
    if overrides:
        preset = preset.with_(compliance=overrides)
    timings["load"] = time.perf_counter() - t0

    t = time.perf_counter()
    step("smooth")
    lost = lost_nodes(tracks)
    smoothed = smooth_tracks(_smoother_input(tracks, lost), graph, preset.smoother)
    if lost:  # downstream sees only what was observed: the lost nodes' stand-in positions are not data
        pre = smoothed.presmoothed
        pre_xy = np.where(tracks.observed[:, :, None], pre.xy, np.nan)
        smoothed = dataclasses.replace(smoothed, observed=tracks.observed.copy(), presmoothed=Tracks(
            node_ids=pre.node_ids, xy=pre_xy, sigma_px=pre.sigma_px, source=pre.source))
    timings["smooth"] = time.perf_counter() - t

    t = time.perf_counter()
    step("bending")
    xy = observed_positions(smoothed)
    raw_xy = smoothed.presmoothed.xy
    geometry = compute_geometry(xy, tracks.node_ids, graph, rest=preset.bending.rest)
    bending = compute_bending(xy, tracks.node_ids, graph, preset.bending, frame_cov=smoothed.frame_cov)
    raw_bending = compute_bending(raw_xy, tracks.node_ids, graph, preset.bending)
    smoothing = SmoothingMetrics(
        bend_rms_raw_deg=filtered_rms(raw_bending), bend_rms_smoothed_deg=filtered_rms(bending),
        edge_cv_raw=length_cv(raw_xy, tracks.node_ids, graph), edge_cv_smoothed=length_cv(xy, tracks.node_ids, graph))
    response = build_response(bending, geometry, preset, skip_nodes=lost)
    timings["bending"] = time.perf_counter() - t

    t = time.perf_counter()
    step("fit")
    weights = response.weights if preset.compliance.weighted else None
    precision = None
    if preset.compliance.correlated:
        if effects:
            raise ValueError(f"preset {preset.name!r}: the correlated fit has no effect terms yet; drop "
                             f"correlated=True or the effects {', '.join(effects)}")
        if response.covariance is None:
            raise ValueError(f"preset {preset.name!r}: correlated=True needs the smoother's marginal covariances")
        precision = response.precision
    boot_info = None
    # single-threaded BLAS: on a long recording the fits' mat-vecs pass OpenBLAS's threading threshold,
    # and its threads busy-waiting on a shared machine made them 25x slower (50,000 frames)
    with single_threaded_blas():
        if effects:
            # the node sets the diagnosis splits its rows by (rce_gtsam.diagnosis.io), so the extended fit keeps
            # the start the diagnosis' candidate keeps
            fit = fit_extended(response.Y, effects, preset.compliance, weights, response.root_distance,
                               edge_nodes=bending.nodes_of(response.bend_rows))
        elif response.Y.shape[0] >= 2 and np.isfinite(response.Y).any(axis=1).all():
            # the rank-1 fit is the response model without effects (the diagnosis baseline is the same fit)
            fit = ResponseModel(config=preset.compliance).fit(response.Y, weights, response.root_distance,
                                                              precision=precision).core
        else:  # a single bend, or a segment with no usable frame (every bend an outlier): the same solver,
            # which leaves such a kappa at 1; the quality verdict flags it (single_bend / low_support), exit 3
            fit = fit_rank1(response.Y, preset.compliance, weights, precision)
        timings["fit"] = time.perf_counter() - t
        if before_bootstrap is not None:
            before_bootstrap(AnalysisResult(graph=graph, tracks=tracks, preset=preset, smoothed=smoothed,
                                            geometry=geometry, bending=bending, raw_bending=raw_bending,
                                            response=response, fit=fit, ci=None, smoothing=smoothing,
                                            timings_s=dict(timings), inputs=dict(inputs), effects=tuple(effects)))
        t = time.perf_counter()
        step("bootstrap")
        if effects:
            ci, boot_info = bootstrap_extended(fit, preset.compliance)
        else:
            ci = bootstrap_kappa(response.Y, preset.compliance, weights, fit=fit, precision=precision)
        time_split = None
        if preset.compliance.time_split_blocks and not effects and ci is not None and preset.compliance.n_boot > 0:
            time_split = time_split_check(response.Y, weights, preset.compliance, fit.kappa, ci.low, ci.high,
                                          preset.compliance.time_split_blocks)
            ci = widen(ci, fit.kappa, time_split.inflation)
    timings["bootstrap"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    return AnalysisResult(graph=graph, tracks=tracks, preset=preset, smoothed=smoothed, geometry=geometry,
                          bending=bending, raw_bending=raw_bending, response=response, fit=fit, ci=ci,
                          smoothing=smoothing, timings_s=timings, inputs=inputs, effects=tuple(effects),
                          effects_bootstrap=boot_info, time_split=time_split)
