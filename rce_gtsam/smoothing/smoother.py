"""GTSAM factor-graph smoother of branch-node tracks, with marginal covariances.

One GTSAM variable per frame 0..F-1 (unobserved frames included): the frame state ``X_t``, the 2N
pixel coordinates of every node at that frame (layout: :mod:`rce_gtsam.factors._frame`).
Factors (see :mod:`rce_gtsam.factors` for the residuals):

* measurement of every node observed at the frame — isotropic or branch-aligned anisotropic 2x2
  noise per observation, optionally a robust loss (Huber / Cauchy) per observation;
* first differences ``p(t+1) - p(t)`` (weight w_v) and second differences
  ``p(t-1) - 2 p(t) + p(t+1)`` (weight w_a) along every node's trajectory;
* an edge prior on every parent -> child edge at every frame: the paper's rest *offset* vector
  (``edge_prior="offset"``) or a rest *length* (``edge_prior="length"``).

Cost (plant 1, 20 nodes x 1104 frames, benchmarks/bench_analyze.py): the linear presets build and solve
in ~0.35 s, 7x a bare scipy sparse solve of the same quadratic. The non-linear options pay one Python
callback per frame and per linearisation: 5-7 s on plant 1 (Huber 8 LM iterations, rest length 7), about
twice the per-node-frame C++ factors they replaced, which made the linear case twice as slow.

With the paper's settings the problem is linear least squares (the same quadratic as the
published LSQR solver, see :mod:`rce_gtsam.smoothing.reference`); it is solved here with GTSAM's
Levenberg-Marquardt in one exact step (the non-linear options take several iterations).
Marginal covariances come from the linearisation at the solution (robust weights included) through
a block-banded selected inversion (:mod:`rce_gtsam.smoothing.marginals`), not per-key ``gtsam.Marginals``.

Long recordings (more than ``SmootherConfig.window_frames`` frames) are solved in overlapping windows
with a burn-in margin each side (:mod:`rce_gtsam.smoothing.windowing`): time and memory grow linearly with the
number of frames, and the window cores match the whole-recording solve to ~1e-9 px.

Variable keys are ``gtsam.symbol('x', t)`` (:func:`rce_gtsam.factors.frame_key`); node row ``i``
(order of ``tracks.node_ids``) occupies entries 2i, 2i+1 of each state. Sorted key order is frame
order, which the marginal computation relies on.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import gtsam
import numpy as np

from ..errors import InputError
from ..factors import (MEASUREMENT_WEIGHT_FLOOR, AccelerationFactor, EdgeLengthFactor,
                      EdgeOffsetFactor, MeasurementFactor, VelocityFactor, frame_key, zero_values)
from ..graph import BranchGraph
from ..presets import SmootherConfig
from .presmooth import moving_average
from ..tracks import Tracks
from .memory import release_freed_memory
from .windowing import plan_windows
from .uniform_sigma import rescale_covariances, uniform_sigma

@dataclass(frozen=True)
class SmootherReport:
    """What the smoother did. Times in seconds; errors are GTSAM's 0.5 * sum of squared whitened
    residuals (robust losses applied).

    converged: linear (paper) problems — the normal-equation residual at the solution is below
    :data:`LINEAR_OPTIMALITY_TOL`; non-linear ones — LM stopped on its error tolerances, before the
    iteration cap and without exhausting its damping range.
    seconds_optimize includes GTSAM's linearisation at the solution (shared with the marginals);
    seconds_marginals is the selected inversion.
    A long recording is solved in ``n_windows`` overlapping windows (:mod:`rce_gtsam.smoothing.windowing`): then
    iterations is the largest over windows, errors / variable and factor counts are sums over windows
    (a margin frame counts in every window that holds it) and converged means every window converged.
    """

    iterations: int
    initial_error: float
    final_error: float
    n_variables: int
    n_factors: int
    converged: bool
    seconds_build: float
    seconds_optimize: float
    seconds_marginals: float
    n_windows: int = 1


@dataclass(frozen=True, eq=False)
class SmoothedTracks:
    """Result of :func:`smooth_tracks`.

    tracks: smoothed positions at ALL frames 0..F-1 (no NaN), pixels.
    observed: (N, F) bool — the input observation mask (downstream paper metrics use only these frames).
    presmoothed: the moving-average tracks that were fed to the graph (what the paper calls "raw").
    cov: (N, F, 2, 2) marginal covariance of each node position, px^2 (None if not computed).
    frame_cov: (F, 2N, 2N) joint covariance of all nodes at each frame, px^2, ordered
        [x0, y0, x1, y1, ...] following ``tracks.node_ids`` (None if not computed). Stored as float32
        (6e-8 relative rounding; it is 16 N^2 bytes per frame, 640 MB at 50,000 frames x 20 nodes in
        float64); ``cov`` holds its 2x2 diagonal blocks in float64.
    report: solver diagnostics.
    """

    tracks: Tracks
    observed: np.ndarray
    presmoothed: Tracks
    cov: np.ndarray | None
    frame_cov: np.ndarray | None
    report: SmootherReport

    def joint_cov(self, nodes: Sequence[int]) -> np.ndarray:
        """(F, 2k, 2k) joint covariance of the given node ids at every frame, ordered
        [x_n0, y_n0, x_n1, y_n1, ...] in the order given (px^2)."""
        if self.frame_cov is None:
            raise ValueError("marginal covariances were not computed (SmootherConfig.marginals=False)")
        rows = [self.tracks.index(int(n)) for n in nodes]
        idx = np.array([[2 * r, 2 * r + 1] for r in rows], dtype=int).reshape(-1)
        return self.frame_cov[:, idx[:, None], idx[None, :]]


# --------------------------------------------------------------------------------------------
# Inputs derived from the pre-smoothed tracks


def initial_positions(tracks: Tracks) -> np.ndarray:
    """(N, F, 2) starting values: the measurement where observed, linear interpolation across gaps,
    the nearest observation before the first / after the last observed frame (pixels)."""
    out = np.empty_like(tracks.xy)
    frames = np.arange(tracks.n_frames)
    obs = tracks.observed
    for i in range(tracks.n_nodes):
        f = np.flatnonzero(obs[i])
        for axis in (0, 1):
            out[i, :, axis] = np.interp(frames, f, tracks.xy[i, f, axis])
    return out


def _edge_rows(tracks: Tracks, graph: BranchGraph) -> list[tuple[int, int, tuple[int, int]]]:
    return [(tracks.index(a), tracks.index(b), (a, b)) for a, b in graph.edges]


def node_tangents(tracks: Tracks, graph: BranchGraph) -> np.ndarray:
    """(N, 2) unit vector along the branch at each node (image axes).

    Definition: the mean of the unit direction vectors (parent -> child) of the node's incident
    edges, each edge's direction taken at the pair's first common observed frame (the paper's
    reference frame). For a chain node this bisects its two segments; for a tip it is its one
    segment. If the directions cancel (a hairpin fold, |mean| < 1e-6) the parent edge's direction
    is used (the root, which has no parent edge, uses its first child edge).
    """
    dirs: dict[int, list[np.ndarray]] = {}
    for ia, ib, (a, b) in _edge_rows(tracks, graph):
        d = EdgeOffsetFactor.rest_offset(tracks.xy[ia], tracks.xy[ib])
        n = np.linalg.norm(d)
        if not n > 0:
            raise InputError(tracks.source, f"nodes {a} and {b} coincide at their first common frame; "
                                            "the branch direction is undefined", f"edge [{a}, {b}]")
        u = d / n
        dirs.setdefault(ia, []).append(u)   # parent: its child edges follow its own parent edge in BFS
        dirs.setdefault(ib, []).insert(0, u)  # child: its parent edge first (the fallback)
    out = np.zeros((tracks.n_nodes, 2))
    for i in range(tracks.n_nodes):
        us = dirs.get(i)
        if not us:
            out[i] = (1.0, 0.0)
            continue
        m = np.mean(us, axis=0)
        nm = np.linalg.norm(m)
        out[i] = m / nm if nm > 1e-6 else us[0]
    return out


def _check_inputs(tracks: Tracks, graph: BranchGraph, config: SmootherConfig) -> None:
    if set(tracks.node_ids.tolist()) != set(graph.nodes) or len(tracks.node_ids) != len(graph.nodes):
        missing = sorted(set(graph.nodes) - set(tracks.node_ids.tolist()))
        extra = sorted(set(tracks.node_ids.tolist()) - set(graph.nodes))
        raise InputError(tracks.source, f"tracks and graph disagree on the nodes (missing from tracks: "
                                        f"{missing}, not in graph: {extra}); graph: {graph.source}")
    obs = tracks.observed
    for i, n in enumerate(tracks.node_ids):
        if not obs[i].any():
            raise InputError(tracks.source, f"node {n} is never observed", f"node {n}")
    for ia, ib, (a, b) in _edge_rows(tracks, graph):
        if config.edge_weight > 0 and not (obs[ia] & obs[ib]).any():
            raise InputError(tracks.source, f"nodes {a} and {b} are never observed in the same frame, "
                                            "so the edge has no rest shape", f"edge [{a}, {b}]")
    if config.velocity_weight <= 0 and config.acceleration_weight <= 0:
        # Without temporal factors each frame stands alone: an unobserved node position is fixed only by
        # the offset prior through an observed node of the same frame (the tree is connected); the
        # length prior fixes only the distance, leaving a direction free.
        need_all = not (config.edge_weight > 0 and config.edge_prior == "offset")
        bad = ~obs if need_all else np.broadcast_to(~obs.any(axis=0), obs.shape)
        if bad.any():
            r, f = np.argwhere(bad)[0]
            raise InputError(tracks.source, "with velocity and acceleration weights both 0, this node position is "
                                            "not determined by any factor (unobserved, no temporal link)",
                             f"node {tracks.node_ids[r]}, frame {f}")
    elif config.velocity_weight <= 0:
        # Acceleration alone leaves a straight-line trend free per node unless two observations pin it.
        few = np.flatnonzero(obs.sum(axis=1) < 2)
        if few.size:
            n = tracks.node_ids[few[0]]
            raise InputError(tracks.source, f"node {n} is observed in fewer than 2 frames; with velocity weight 0 "
                                            "its trajectory's slope is not determined", f"node {n}")
    if config.robust not in (None, "huber", "cauchy"):
        raise ValueError(f"SmootherConfig.robust must be None, 'huber' or 'cauchy', got {config.robust!r}")
    if config.edge_prior not in ("offset", "length"):
        raise ValueError(f"SmootherConfig.edge_prior must be 'offset' or 'length', got {config.edge_prior!r}")
    if not config.along_across_ratio > 0:
        raise ValueError(f"SmootherConfig.along_across_ratio must be > 0, got {config.along_across_ratio!r}")
    if tracks.sigma_px is not None:
        s = tracks.sigma_px[obs]
        if not (np.isfinite(s) & (s > 0)).all():
            r, f = np.argwhere(obs & ~(np.isfinite(tracks.sigma_px) & (tracks.sigma_px > 0)))[0]
            raise InputError(tracks.source, "sigma_px must be finite and > 0 at every observation",
                             f"node {tracks.node_ids[r]}, frame {f}")


# --------------------------------------------------------------------------------------------
# Graph construction


@dataclass(frozen=True)
class FactorGraphProblem:
    """A built smoother problem: the GTSAM graph, initial values and the variable layout."""

    graph: gtsam.NonlinearFactorGraph
    initial: gtsam.Values
    n_nodes: int
    n_frames: int

    def key(self, frame: int) -> int:
        """Key of the frame state at ``frame``."""
        return frame_key(frame)

    def keys(self) -> list[int]:
        """Frame-state keys in frame order."""
        return [frame_key(t) for t in range(self.n_frames)]

    def positions(self, values: gtsam.Values) -> np.ndarray:
        """(N, F, 2) positions from a Values holding every frame state (pixels)."""
        if int(values.size()) != self.n_frames or int(values.dim()) != 2 * self.n_nodes * self.n_frames:
            raise RuntimeError(f"expected {self.n_frames} frame states of size {2 * self.n_nodes}, got "
                               f"{values.size()} variables of total size {values.dim()}")
        X = np.stack([values.atVector(k) for k in self.keys()])   # (F, 2N)
        return X.reshape(self.n_frames, self.n_nodes, 2).transpose(1, 0, 2).copy()


@dataclass(frozen=True, eq=False)
class RestShape:
    """What the priors take from the whole recording, so that every window of a long one uses the same.

    pairs: (E, 2) node rows (parent, child) of every graph edge.
    tangents: (N, 2) unit branch directions for the anisotropic measurement noise (None if isotropic).
    offsets: (E, 2) rest offsets d_ab of the ``"offset"`` edge prior, px (None otherwise).
    lengths: (E,) rest lengths of the ``"length"`` edge prior, px (None otherwise).
    """

    pairs: np.ndarray
    tangents: np.ndarray | None = None
    offsets: np.ndarray | None = None
    lengths: np.ndarray | None = None


def rest_shape(pre: Tracks, graph: BranchGraph, config: SmootherConfig) -> RestShape:
    """The :class:`RestShape` of pre-smoothed tracks (first common frames, medians: see the factors)."""
    rows = _edge_rows(pre, graph)
    pairs = np.array([(ia, ib) for ia, ib, _ in rows], dtype=np.int64).reshape(-1, 2)
    tangents = node_tangents(pre, graph) if config.along_across_ratio != 1.0 else None
    offsets = lengths = None
    if config.edge_weight > 0 and config.edge_prior == "offset":
        offsets = np.array([EdgeOffsetFactor.rest_offset(pre.xy[ia], pre.xy[ib]) for ia, ib, _ in rows])
    elif config.edge_weight > 0:
        lengths = np.array([EdgeLengthFactor.rest_length(pre.xy[ia], pre.xy[ib]) for ia, ib, _ in rows])
    return RestShape(pairs=pairs, tangents=tangents, offsets=offsets, lengths=lengths)


def build_problem(pre: Tracks, graph: BranchGraph, config: SmootherConfig,
                  shape: RestShape | None = None) -> FactorGraphProblem:
    """Build the factor graph for already pre-smoothed tracks (no moving average applied here).

    ``shape``: rest shape and tangents to use (a window of a long recording passes the whole
    recording's); None = check the inputs and take them from ``pre``.

    Weight guards follow the paper (§2.2): the measurement weight is floored at 1e-9; any other
    factor family whose weight is <= 0 is left out.
    """
    if shape is None:
        _check_inputs(pre, graph, config)
        shape = rest_shape(pre, graph, config)
    N, F = pre.n_nodes, pre.n_frames
    K = [frame_key(t) for t in range(F)]
    zeros = zero_values(K, N)
    fg = gtsam.NonlinearFactorGraph()
    add = fg.add
    obs = pre.observed

    # Measurements: one factor per frame covering its observed nodes, each with its own 2x2 noise.
    tangents = shape.tangents if shape.tangents is not None else [None] * N
    sigma_default = 1.0 / np.sqrt(max(float(config.measurement_weight), MEASUREMENT_WEIGHT_FLOOR))
    sqrt_info = MeasurementFactor.sqrt_information
    if pre.sigma_px is None:
        W = np.stack([sqrt_info(sigma_default, tangents[i], config.along_across_ratio) for i in range(N)])
        W_of = lambda rows, t: W[rows]  # noqa: E731
    else:
        W_unit = np.stack([sqrt_info(1.0, tangents[i], config.along_across_ratio) for i in range(N)])
        W_of = lambda rows, t: W_unit[rows] / pre.sigma_px[rows, t][:, None, None]  # noqa: E731
    for t in range(F):
        rows = np.flatnonzero(obs[:, t])
        if rows.size:
            add(MeasurementFactor.create(K[t], N, rows, pre.xy[rows, t], W_of(rows, t), zeros,
                                         config.robust, config.robust_k))

    # Temporal smoothness along every trajectory.
    if config.velocity_weight > 0:
        for t in range(F - 1):
            add(VelocityFactor.create(K[t], K[t + 1], N, config.velocity_weight, zeros))
    if config.acceleration_weight > 0 and F >= 3:
        for t in range(1, F - 1):
            add(AccelerationFactor.create(K[t - 1], K[t], K[t + 1], N, config.acceleration_weight, zeros))

    # Edge shape prior at every frame.
    if shape.offsets is not None:
        for t in range(F):
            add(EdgeOffsetFactor.create(K[t], N, shape.pairs, shape.offsets, config.edge_weight, zeros))
    elif shape.lengths is not None:
        for t in range(F):
            add(EdgeLengthFactor.create(K[t], N, shape.pairs, shape.lengths, config.edge_weight))

    init = gtsam.Values()
    x0 = initial_positions(pre).transpose(1, 0, 2).reshape(F, 2 * N)
    for k, x in zip(K, x0):
        init.insert(k, x)
    return FactorGraphProblem(graph=fg, initial=init, n_nodes=N, n_frames=F)


def is_linear(config: SmootherConfig) -> bool:
    """True if every factor is linear in the positions with a fixed Gaussian noise model (the paper
    model): then one Gauss-Newton step from any start is the exact least-squares solution."""
    return config.robust is None and (config.edge_prior == "offset" or config.edge_weight <= 0)


#: Optimality test for the linear case: ||J^T r||_inf / (||J||_F ||r||_2) at the solution, the
#: scale-free normal-equation residual LSQR also uses. 1e-8 is ~1e8 times double-precision rounding
#: of a 1e5-row system and far below the paper's LSQR tolerance (1e-6).
LINEAR_OPTIMALITY_TOL = 1e-8


def lm_params(problem: FactorGraphProblem, linear: bool) -> gtsam.LevenbergMarquardtParams:
    """LM settings.

    Linear problems: ``lambdaInitial = 1e-9`` (every node-frame is constrained, so an almost undamped
    step is the exact solution — measured 2e-8 px from a direct sparse solve on both plants) and a
    single iteration: a second one would only re-solve the same system to confirm a zero step;
    optimality is checked instead with the normal-equation residual (see :data:`LINEAR_OPTIMALITY_TOL`).

    Nonlinear problems (range prior, robust loss): diagonal (Marquardt) damping, which scales the
    damping to each variable's curvature (unobserved frames are much weaker than observed ones), and
    GTSAM's default error tolerances (1e-5 relative / absolute). On plant 1 with raw tracks the
    undamped-identity default stopped on a plateau 1.3% above the minimum that diagonal damping reaches.

    Ordering: GTSAM's default COLAMD (measured faster than the frame-major banded ordering).
    """
    params = gtsam.LevenbergMarquardtParams()
    if linear:
        params.setMaxIterations(1)
        params.setlambdaInitial(1e-9)
    else:
        params.setMaxIterations(100)
        params.setDiagonalDamping(True)
    return params


def normal_equation_residual(A, b: np.ndarray) -> float:
    """||A^T b||_inf / (||A||_F ||b||_2) for the whitened linearisation ``A delta = b`` at a candidate
    solution (``b`` = minus the whitened residual): 0 at an exact least-squares minimum."""
    g = np.abs(A.T @ b).max() if A.nnz else 0.0
    scale = float(np.sqrt(A.multiply(A).sum())) * float(np.linalg.norm(b))
    return float(g / scale) if scale > 0 else 0.0


def optimize(problem: FactorGraphProblem, linear: bool) -> tuple[gtsam.Values, dict]:
    """Run GTSAM Levenberg-Marquardt; returns the solution and iteration/error diagnostics."""
    params = lm_params(problem, linear)
    opt = gtsam.LevenbergMarquardtOptimizer(problem.graph, problem.initial, params)
    initial_error = opt.error()  # the optimizer state evaluates it on construction
    result = opt.optimize()
    iters = int(opt.iterations())
    # LM also gives up when lambda exceeds its upper bound (no step decreases the error): not converged.
    converged = iters < params.getMaxIterations() and opt.lambda_() < params.getlambdaUpperBound()
    return result, {"iterations": iters, "initial_error": float(initial_error),
                    "final_error": float(opt.error()), "converged": bool(converged)}


def smooth_tracks(tracks: Tracks, graph: BranchGraph, config: SmootherConfig) -> SmoothedTracks:
    """Pre-smooth with :func:`~rce_gtsam.smoothing.presmooth.moving_average` (``config.presmooth_window``), then
    solve the factor graph with GTSAM LM and (if ``config.marginals``) compute marginal covariances.

    Raises :class:`~rce_gtsam.errors.InputError` if tracks and graph do not match, a node is never
    observed or an edge's nodes are never observed together.
    """
    from .marginals import single_threaded_blas

    with single_threaded_blas():  # see marginals.single_threaded_blas: small matrices, shared cores
        return _smooth_tracks(tracks, graph, config)


def _smooth_tracks(tracks: Tracks, graph: BranchGraph, config: SmootherConfig) -> SmoothedTracks:
    _check_inputs(tracks, graph, config)
    pre = moving_average(tracks, config.presmooth_window)
    solve_in, ratio = uniform_sigma(pre) if config.sigma_mode == "uniform" else (pre, None)
    linear = is_linear(config)
    shape = rest_shape(pre, graph, config)
    windows = plan_windows(pre.observed, config.window_frames, config.window_margin)
    _check_windows(pre, windows, config)
    N, F = pre.n_nodes, pre.n_frames
    xy = np.empty((N, F, 2))
    cov = frame_cov = None
    if config.marginals:
        cov = np.empty((N, F, 2, 2))
        frame_cov = np.empty((F, 2 * N, 2 * N), dtype=np.float32)
    parts = []
    for w in windows:
        part = _solve_window(_frames(solve_in, w.lo, w.hi), graph, config, shape, linear, w.lo)
        xy[:, w.core_lo:w.core_hi] = part.xy[:, w.core]
        if config.marginals:
            fc = part.frame_cov[w.core]
            idx = np.arange(N)
            cov[:, w.core_lo:w.core_hi] = fc.reshape(-1, N, 2, N, 2)[:, idx, :, idx, :]
            frame_cov[w.core_lo:w.core_hi] = fc
        parts.append(part.report)
        del part
        release_freed_memory()  # this window's GTSAM heap (and the loader's), before more arrays are made
    report = SmootherReport(
        iterations=max(r.iterations for r in parts), initial_error=sum(r.initial_error for r in parts),
        final_error=sum(r.final_error for r in parts), n_variables=sum(r.n_variables for r in parts),
        n_factors=sum(r.n_factors for r in parts), converged=all(r.converged for r in parts),
        seconds_build=sum(r.seconds_build for r in parts), seconds_optimize=sum(r.seconds_optimize for r in parts),
        seconds_marginals=sum(r.seconds_marginals for r in parts), n_windows=len(windows))
    if ratio is not None and config.marginals:
        rescale_covariances(cov, frame_cov, ratio)
    out = Tracks(node_ids=tracks.node_ids.copy(), xy=xy, sigma_px=None, source=tracks.source)
    return SmoothedTracks(tracks=out, observed=tracks.observed.copy(), presmoothed=pre, cov=cov,
                          frame_cov=frame_cov, report=report)


def _frames(tracks: Tracks, lo: int, hi: int) -> Tracks:
    """Frames lo:hi of ``tracks`` (views, no copy)."""
    if lo == 0 and hi == tracks.n_frames:
        return tracks
    sigma = None if tracks.sigma_px is None else tracks.sigma_px[:, lo:hi]
    return Tracks(node_ids=tracks.node_ids, xy=tracks.xy[:, lo:hi], sigma_px=sigma, source=tracks.source)


def _check_windows(pre: Tracks, windows, config: SmootherConfig) -> None:
    """A node needs observations inside every window it is solved in (two with acceleration alone,
    which leaves a straight-line trend free), unless the offset prior ties it to the other nodes."""
    if len(windows) == 1 or (config.edge_weight > 0 and config.edge_prior == "offset"):
        return
    need = 1 if config.velocity_weight > 0 or config.acceleration_weight <= 0 else 2
    obs = pre.observed
    for w in windows:
        few = np.flatnonzero(obs[:, w.lo:w.hi].sum(axis=1) < need)
        if few.size:
            n = pre.node_ids[few[0]]
            raise InputError(pre.source, f"node {n} is observed in fewer than {need} of frames {w.lo}-{w.hi - 1}; "
                                         f"recordings longer than {config.window_frames} frames are smoothed in "
                                         f"windows (smoother.window_frames) and each needs the node",
                             f"node {n}")


@dataclass(frozen=True, eq=False)
class _WindowResult:
    xy: np.ndarray                # (N, Fw, 2) px
    frame_cov: np.ndarray | None  # (Fw, 2N, 2N) px^2, float64
    report: SmootherReport


def _solve_window(pre: Tracks, graph: BranchGraph, config: SmootherConfig, shape: RestShape, linear: bool,
                  first_frame: int) -> _WindowResult:
    """Build, solve and (if configured) take the marginals of one window's factor graph."""
    from .marginals import frame_marginals, whitened_jacobian  # local: marginals uses this key layout

    t0 = time.perf_counter()
    problem = build_problem(pre, graph, config, shape)
    t1 = time.perf_counter()
    result, diag = optimize(problem, linear)
    jacobian = None
    if linear or config.marginals:  # GTSAM's whitened linearisation at the solution, shared below
        jacobian, rhs = whitened_jacobian(problem.graph.linearize(result), n_cols=int(result.dim()))
    if linear:  # one exact step: confirm optimality
        diag["converged"] = normal_equation_residual(jacobian, rhs) < LINEAR_OPTIMALITY_TOL
    t2 = time.perf_counter()
    xy = problem.positions(result)
    frame_cov = None
    if config.marginals:
        frame_cov = frame_marginals(problem.graph, result, problem.n_nodes, problem.n_frames, jacobian=jacobian,
                                    first_frame=first_frame)
    t3 = time.perf_counter()
    report = SmootherReport(iterations=diag["iterations"], initial_error=diag["initial_error"],
                            final_error=diag["final_error"], n_variables=int(problem.initial.size()),
                            n_factors=int(problem.graph.size()), converged=diag["converged"],
                            seconds_build=t1 - t0, seconds_optimize=t2 - t1, seconds_marginals=t3 - t2)
    return _WindowResult(xy=xy, frame_cov=frame_cov, report=report)
