"""3-D GTSAM smoother of branch nodes seen by a colour camera with registered depth (mm in the camera frame).

One GTSAM variable per frame ``X_t`` (3N entries: node row i at 3i..3i+2, x right, y down, z forward, mm).
Factors, all on the same frames and nodes as the 2-D smoother (:mod:`.smoother`):

* pixel measurement of every observed node, the pinhole projection ``u = fx x / z + cx``,
  ``v = fy y / z + cy`` written as ``(fx x - (u - cx) z) / z0`` and ``(fy y - (v - cy) z) / z0`` (linear in the
  point; equal to the pixel error times ``z / z0``, with ``z0`` the node's current depth estimate, so its
  sigma is the tracker's ``sigma_px``); re-linearised once at the solution;
* depth measurement ``z - z_meas`` with the node's own depth sigma (:mod:`rce_gtsam.track.depth_sample`); a depth
  more than :data:`DEPTH_GATE` sigmas from the first solution is dropped (background or speckle leaking into the
  window) and the graph solved again;
* first and second differences along each node's trajectory (mm), and the edge-offset prior on the *projected*
  child-minus-parent offset, ``fx (x_c / z0_c - x_p / z0_p)`` and likewise in y, toward its rest offset (px, the
  per-edge median over frames): the 2-D smoother's edge factor on what the image shows. It leaves z free: a
  prior on the 3-D offset, or on its x and y in mm, is met by sliding the nodes along their rays, and pinned the
  out-of-plane swing to the rest shape (tip depth error 4-10 mm against 3 mm raw on a simulated chain,
  kappa log-RMSE 0.06-0.08 against 0.04-0.06 without it). Velocity and acceleration take the 2-D smoother's
  weights (``SmootherConfig``, 1/px^2) turned into mm at the branch's median depth (``mm_per_px = median z / fx``),
  so a 3-D recording is smoothed as strongly in time as its 2-D tracks are;
* optionally (``stretch_rel``, off by default), inextensibility: every segment keeps one 3-D length, a free
  variable per edge (:data:`STRETCH_REL`, with the measurements that keep it off by default).

Every factor is linear, so each solve is one Levenberg-Marquardt step over ``LinearContainerFactor``s (C++;
the Python ``CustomFactor`` route is ~100x slower, see docs/ecosystem notes). Marginal covariances per frame
come from ``gtsam.Marginals``. The whole recording is one graph (no windowing): fine for minutes of 30 fps video.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np

from ..camera import CameraIntrinsics
from ..errors import InputError
from ..graph import BranchGraph
from ..presets import SmootherConfig
from .presmooth import moving_average_1d

#: The depth axis' acceleration sigma is a factor times each node's RMS image-plane acceleration (mm, from its
#: pre-smoothed pixel track at its depth): how fast the branch may move toward the camera, relative to how fast
#: it is seen to move across the image. The factor is chosen from Z_ACCEL_GRID by cross-validation on the depth
#: itself: blocks of CV_BLOCK frames, every CV_EVERY-th block, are held out (blocks, so that depth errors
#: correlated over a few frames cannot predict themselves), the rest smoothed with each factor (one
#: linearisation), and the factor whose prediction of the held-out depths has the least mean squared
#: standardised error (capped at the gate) wins. This picks the best *depth*, not the best kappa: on simulated
#: out-of-plane recordings it mostly picks 2 (the true depth acceleration is ~0.7 of the image's), while kappa
#: alone would prefer smoother depth (see benchmarks/bench_depth3d.py, which scores each factor). On 20 simulated
#: recordings it picked the grid's loosest value every time (kappa log-RMSE median 0.308 there, 0.311 at 1,
#: 0.337 at 0.5, 0.357 at 0.25). It costs 4 extra solves: 2.7 s against 1.1 s with a given factor and 0.1-0.3 s
#: for the 2-D smoother (20 nodes x 300 frames, docs/validation/depth3d.json).
Z_ACCEL_GRID = (2.0, 1.0, 0.5, 0.25)
CV_EVERY = 5
CV_BLOCK = 8
#: Solves per fit: the projections' depths are re-linearised at the first solution (and the depths gated).
N_LINEARISATIONS = 2
#: Extra solves with the inextensibility factor (its directions re-linearised at each solution).
STRETCH_LINEARISATIONS = 1

#: Inextensibility: a branch segment does not stretch, so each edge's 3-D length |p_c - p_p| is one constant L_e
#: (mm, a free variable of the graph, estimated with the positions). Its factor per edge and frame is the
#: linearisation ``u . (p_c - p_p) - L_e = 0`` with ``u`` the current unit direction (exact to first order,
#: re-linearised like the projections). Its sigma combines STRETCH_REL * L_e (L_e the first solution's median
#: length) with the robust scatter of that solution's lengths over frames (:func:`_stretch_sigma`). STRETCH_REL:
#: the chord between two tracked points on a stem changes by the stem's axial strain (well under 1e-3 for a stem
#: bent by wind) plus the points' offset from the stem's axis times the bend (radius ~1-3 mm x a few degrees,
#: ~0.1-0.2 mm, under 1 % of a 15-30 mm segment); 1 % bounds both. With pixels good to a fraction of a pixel the
#: depth difference along a segment tilted out of the image plane then follows from its projected length
#: (d dz = L dL / dz), and depth is needed mostly for the sign and the scale. It constrains no direction, so the
#: out-of-plane swing stays free (unlike a prior on the 3-D offset, see above).
#: Measured (benchmarks/bench_depth3d.py --oracles, 20 simulated out-of-plane recordings, kappa log-RMSE median):
#: with 0.1 px pixel tracks and D435i depth noise it cuts the 3-D kappa error from 0.143 to 0.097 (better on 18 of
#: 20; the 2-D pipeline on those pixels: 0.182); with the default tracker-noise model's pixels (~0.8 px, along the
#: stem 3x across) it raises it from 0.312 to 0.447, because the length then turns the pixel error along the
#: segment into depth error (x L/dz, 2-4 here); on the rendered runs' tracks (median 0.07 px, 4.5 % off by > 1 px)
#: 0.409 against 0.415. So it is off by default (``smooth_tracks_3d(stretch_rel=STRETCH_REL)`` switches it on).
STRETCH_REL = 0.01
LENGTH_KEY = gtsam.symbol("l", 0)

#: Depth measurements further than this many sigmas from the first solution are dropped before the final solve.
DEPTH_GATE = 4.0


@dataclass(frozen=True)
class Smoother3DReport:
    """What the 3-D smoother did. Seconds; counts; ``mm_per_px`` scales the 2-D weights to mm;
    ``z_accel_factor`` the depth axis' acceleration factor used and ``z_accel_cv`` its cross-validation scores
    (factor -> mean squared standardised held-out depth error; empty when the factor was given).
    ``stretch_rel``: the inextensibility sigma's share of a segment's length (None: no such factor);
    ``lengths_mm``: the estimated 3-D length per edge (mm, ``graph.edges`` order among the tracked nodes);
    ``length_rms_mm``: RMS of |p_c - p_p| - L_e over edges and frames (mm), ``length_rms_sigmas`` the same in
    units of the factor's sigma (about 1 or below when the segments keep their length within the model)."""

    iterations: int
    z_accel_factor: float | None
    z_accel_cv: dict
    n_variables: int
    n_factors: int
    n_depth: int
    n_depth_dropped: int
    mm_per_px: float
    seconds_build: float
    seconds_optimize: float
    seconds_marginals: float
    stretch_rel: float | None = None
    lengths_mm: tuple | None = None
    length_rms_mm: float | None = None
    length_rms_sigmas: float | None = None

    @property
    def seconds_total(self) -> float:
        return self.seconds_build + self.seconds_optimize + self.seconds_marginals


@dataclass(frozen=True, eq=False)
class Smoothed3D:
    """Smoothed 3-D node positions.

    node_ids: (N,) rows of the arrays. xyz_mm: (N, F, 3) camera frame, mm, every frame.
    observed: (N, F) bool, the pixel observation mask. depth_used: (N, F) bool, depth factors kept.
    frame_cov: (F, 3N, 3N) float32 joint covariance per frame (mm^2), or None. cov: (N, F, 3, 3) its blocks.
    """

    node_ids: np.ndarray
    xyz_mm: np.ndarray
    observed: np.ndarray
    depth_used: np.ndarray
    frame_cov: np.ndarray | None
    cov: np.ndarray | None
    report: Smoother3DReport

    @property
    def sigma_mm(self) -> np.ndarray | None:
        """(N, F, 3) marginal 1-sigma per axis (mm), or None."""
        return None if self.cov is None else np.sqrt(np.einsum("nfii->nfi", self.cov))


def _presmooth(values: np.ndarray, mask: np.ndarray, window: int) -> np.ndarray:
    """Moving average of each row's observed samples (NaN elsewhere), gaps skipped as in the 2-D smoother."""
    out = np.full(values.shape, np.nan)
    for i in range(values.shape[0]):
        m = mask[i]
        if m.any():
            out[i, m] = moving_average_1d(values[i, m], window)
    return out


def _fill(values: np.ndarray, mask: np.ndarray, fallback: float) -> np.ndarray:
    """Linear interpolation of each row over its masked samples; ``fallback`` for a row with none."""
    out = np.empty(values.shape)
    frames = np.arange(values.shape[1])
    for i in range(values.shape[0]):
        m = mask[i]
        out[i] = np.interp(frames, frames[m], values[i, m]) if m.any() else fallback
    return out


def _check(xy, sigma_px, z_mm, z_sigma_mm, node_ids, source) -> None:
    n, f = xy.shape[:2]
    if xy.shape != (n, f, 2) or z_mm.shape != (n, f) or z_sigma_mm.shape != (n, f) or len(node_ids) != n:
        raise InputError(source, f"3-D smoother inputs disagree: xy {xy.shape}, z {z_mm.shape}, "
                                 f"z sigma {z_sigma_mm.shape}, {len(node_ids)} node ids")
    has_z = np.isfinite(z_mm)
    if not has_z.any():
        raise InputError(source, "no node has a depth in any frame: the recording's depth is empty at the nodes")
    bad = has_z & ~(np.isfinite(z_sigma_mm) & (z_sigma_mm > 0) & (z_mm > 0))
    if bad.any():
        i, t = np.argwhere(bad)[0]
        raise InputError(source, "depth and its sigma must be > 0 mm where a depth is given",
                         f"node {int(node_ids[i])}, frame {int(t)}")
    if sigma_px is not None:
        obs = np.isfinite(xy).all(axis=2)
        if (obs & ~(np.isfinite(sigma_px) & (sigma_px > 0))).any():
            i, t = np.argwhere(obs & ~(np.isfinite(sigma_px) & (sigma_px > 0)))[0]
            raise InputError(source, "sigma_px must be > 0 at every observation", f"node {int(node_ids[i])}, frame {int(t)}")


class _Graph:
    """Builds the linear factors of one solve."""

    def __init__(self, n: int, f: int, n_lengths: int = 0):
        self.n, self.f = n, f
        self.graph = gtsam.NonlinearFactorGraph()
        self.zero = gtsam.Values()
        for t in range(f):
            self.zero.insert(gtsam.symbol("x", t), np.zeros(3 * n))
        if n_lengths:  # the segments' 3-D lengths (mm), one free constant per edge
            self.zero.insert(LENGTH_KEY, np.zeros(n_lengths))

    def add(self, blocks: list[tuple[int, np.ndarray]], b: np.ndarray, sigmas: np.ndarray) -> None:
        """A linear factor ``sum A_t x_t = b``; a block's frame ``t`` of ``None`` is the lengths' variable."""
        keys = [(LENGTH_KEY if t is None else gtsam.symbol("x", t), np.asarray(A, float)) for t, A in blocks]
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, float))
        if len(keys) == 1:
            jf = gtsam.JacobianFactor(keys[0][0], keys[0][1], np.asarray(b, float), noise)
        elif len(keys) == 2:
            jf = gtsam.JacobianFactor(keys[0][0], keys[0][1], keys[1][0], keys[1][1], np.asarray(b, float), noise)
        else:
            jf = gtsam.JacobianFactor(keys[0][0], keys[0][1], keys[1][0], keys[1][1], keys[2][0], keys[2][1],
                                      np.asarray(b, float), noise)
        self.graph.add(gtsam.LinearContainerFactor(jf, self.zero))


def _build(xy, sig_px, z, z_sig, use_depth, lin, edges_rows, rest, cam: CameraIntrinsics,
           cfg: SmootherConfig, mm_per_px: float, z_accel_mm: np.ndarray | None = None,
           stretch_mm: np.ndarray | None = None) -> _Graph:
    """The linear factors, linearised at ``lin`` (N, F, 3) mm (the projections' depths and, with ``stretch_mm``
    (E,) the inextensibility sigmas per edge in mm, the segments' directions)."""
    n, f = xy.shape[:2]
    z0 = np.maximum(lin[..., 2], 1.0)
    g = _Graph(n, f, len(edges_rows) if stretch_mm is not None else 0)
    eye = np.eye(3 * n)
    obs = np.isfinite(xy).all(axis=2)
    for t in range(f):
        rows, b, s = [], [], []
        for i in np.flatnonzero(obs[:, t]):
            ru = np.zeros(3 * n)
            rv = np.zeros(3 * n)
            ru[3 * i], ru[3 * i + 2] = cam.fx / z0[i, t], -(xy[i, t, 0] - cam.cx) / z0[i, t]
            rv[3 * i + 1], rv[3 * i + 2] = cam.fy / z0[i, t], -(xy[i, t, 1] - cam.cy) / z0[i, t]
            rows += [ru, rv]
            b += [0.0, 0.0]
            s += [sig_px[i, t]] * 2
            if use_depth[i, t]:
                rz = np.zeros(3 * n)
                rz[3 * i + 2] = 1.0
                rows.append(rz)
                b.append(z[i, t])
                s.append(z_sig[i, t])
        if rows:
            g.add([(t, np.array(rows))], np.array(b), np.array(s))
        if cfg.edge_weight > 0 and edges_rows:  # on the projected offsets (px), as in 2-D; z is left free
            A = np.zeros((2 * len(edges_rows), 3 * n))
            for k, (ip, ic) in enumerate(edges_rows):
                for ax, foc in ((0, cam.fx), (1, cam.fy)):
                    A[2 * k + ax, 3 * ic + ax] = foc / z0[ic, t]
                    A[2 * k + ax, 3 * ip + ax] = -foc / z0[ip, t]
            g.add([(t, A)], rest.reshape(-1), np.full(2 * len(edges_rows), 1.0 / np.sqrt(cfg.edge_weight)))
        if stretch_mm is not None:  # u . (p_c - p_p) - L_e = 0
            e = len(edges_rows)
            ip, ic = (np.array(v) for v in zip(*edges_rows))
            d = lin[ic, t] - lin[ip, t]
            u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
            A = np.zeros((e, 3 * n))
            for k in range(3):
                A[np.arange(e), 3 * ic + k] += u[:, k]
                A[np.arange(e), 3 * ip + k] -= u[:, k]
            g.add([(t, A), (None, -np.eye(e))], np.zeros(e), stretch_mm)
    if cfg.velocity_weight > 0:
        sv = np.full(3 * n, mm_per_px / np.sqrt(cfg.velocity_weight))
        for t in range(f - 1):
            g.add([(t, -eye), (t + 1, eye)], np.zeros(3 * n), sv)
    if cfg.acceleration_weight > 0:
        sa = np.full(3 * n, mm_per_px / np.sqrt(cfg.acceleration_weight))
        if z_accel_mm is not None:
            sa[2::3] = np.minimum(sa[2::3], z_accel_mm)
        for t in range(1, f - 1):
            g.add([(t - 1, eye), (t, -2 * eye), (t + 1, eye)], np.zeros(3 * n), sa)
    return g


def _image_accel_mm(pre_xy: np.ndarray, z0: np.ndarray, cam: CameraIntrinsics) -> np.ndarray:
    """(N,) RMS second difference of each node's pre-smoothed pixel track, in mm at its median depth (floor 0.01)."""
    acc = pre_xy[:, 2:] - 2 * pre_xy[:, 1:-1] + pre_xy[:, :-2]
    with np.errstate(invalid="ignore"):
        rms_px = np.sqrt(np.nanmean(np.sum(acc * acc, axis=-1), axis=1) / 2)
    rms_px = np.where(np.isfinite(rms_px), rms_px, np.nanmedian(rms_px))
    return np.maximum(rms_px * np.median(z0, axis=1) / cam.fx, 0.01)


def _lengths(xyz: np.ndarray, edges_rows) -> np.ndarray:
    """(E, F) 3-D length of every edge (mm) in every frame."""
    ip, ic = (np.array(v) for v in zip(*edges_rows))
    return np.linalg.norm(xyz[ic] - xyz[ip], axis=-1)


def _stretch_sigma(lengths: np.ndarray, stretch_rel: float) -> np.ndarray:
    """(E,) sigma (mm) of each edge's inextensibility factor from its lengths (E, F) in a solution without it:
    the stem's own stretch (``stretch_rel`` x the median length) combined with the lengths' robust scatter over
    frames (1.4826 MAD), which holds the tracked points' sliding along the stem and the depth noise: the factor is
    never trusted more than the data show the segment keeps its length."""
    med = np.median(lengths, axis=1)
    mad = 1.4826 * np.median(np.abs(lengths - med[:, None]), axis=1)
    return np.hypot(stretch_rel * med, mad)


def _solve(g: _Graph) -> tuple[gtsam.Values, int]:
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(10)
    opt = gtsam.LevenbergMarquardtOptimizer(g.graph, g.zero, params)
    values = opt.optimize()
    return values, int(opt.iterations())


def _positions(values: gtsam.Values, n: int, f: int) -> np.ndarray:
    return np.stack([values.atVector(gtsam.symbol("x", t)).reshape(n, 3) for t in range(f)], axis=1)


def smooth_tracks_3d(xy_px: np.ndarray, sigma_px: np.ndarray | None, z_mm: np.ndarray, z_sigma_mm: np.ndarray,
                     node_ids, graph: BranchGraph, intrinsics: CameraIntrinsics,
                     config: SmootherConfig = SmootherConfig(), source: str = "tracks",
                     z_accel_factor: float | str | None = "cv",
                     stretch_rel: float | None = None) -> Smoothed3D:
    """Smooth pixel tracks ``xy_px`` (N, F, 2; NaN = not observed) with their depths ``z_mm`` (N, F; NaN = none)
    into 3-D positions (mm, camera frame) with marginal covariances. ``sigma_px`` (N, F) per-observation pixel
    sigma (None: ``1/sqrt(config.measurement_weight)``); ``z_sigma_mm`` (N, F) depth sigma."""
    t0 = time.perf_counter()
    xy = np.asarray(xy_px, float)
    z_in = np.asarray(z_mm, float)
    zs = np.asarray(z_sigma_mm, float)
    node_ids = np.asarray(node_ids, int)
    _check(xy, sigma_px, z_in, zs, node_ids, source)
    n, f = xy.shape[:2]
    obs = np.isfinite(xy).all(axis=2)
    has_z = np.isfinite(z_in) & obs
    sig = np.full((n, f), 1.0 / np.sqrt(config.measurement_weight)) if sigma_px is None else np.asarray(sigma_px, float)
    w = config.presmooth_window
    pre_xy = np.stack([_presmooth(xy[..., k], obs, w) for k in range(2)], axis=-1)
    pre_z = _presmooth(z_in, has_z, w)
    z_med = float(np.median(pre_z[has_z]))
    z0 = _fill(pre_z, has_z, z_med)
    xy0 = np.stack([_fill(pre_xy[..., k], obs, float(np.nanmedian(pre_xy[..., k]))) for k in range(2)], axis=-1)
    mm_per_px = z_med / intrinsics.fx
    row = {int(nid): i for i, nid in enumerate(node_ids)}
    edges_rows = [(row[p], row[c]) for p, c in graph.edges if p in row and c in row]
    rest = np.array([np.median(xy0[c] - xy0[p], axis=0) for p, c in edges_rows]).reshape(-1, 2)  # px
    init = intrinsics.deproject(xy0, z0)

    stretch_on = stretch_rel is not None and bool(edges_rows)

    def fit(use0, pre_z_, z_acc, n_lin=N_LINEARISATIONS, stretch=False):
        lin, use, iters, s_mm = init, use0, 0, None
        for k in range(n_lin + (STRETCH_LINEARISATIONS if stretch else 0)):
            g = _build(pre_xy, sig, pre_z_, zs, use, lin, edges_rows, rest, intrinsics, config, mm_per_px,
                       z_acc, s_mm)
            values, it = _solve(g)
            iters += it
            lin = _positions(values, n, f)
            if k == 0:  # gate the depths against the first solution; the segments' lengths from it
                use = use0 & (np.where(use0, np.abs(pre_z_ - lin[..., 2]) / zs, 0.0) <= DEPTH_GATE)
                if stretch:
                    s_mm = _stretch_sigma(_lengths(lin, edges_rows), stretch_rel)
        return g, values, lin, use, iters

    accel_mm = _image_accel_mm(pre_xy, z0, intrinsics)
    t_build = time.perf_counter() - t0
    t1 = time.perf_counter()
    scores: dict[float, float] = {}
    if z_accel_factor == "cv":
        held = has_z & ((np.arange(f) // CV_BLOCK) % CV_EVERY == CV_EVERY // 2)[None, :]
        pre_cv = _presmooth(z_in, has_z & ~held, w)
        for fac in Z_ACCEL_GRID:
            xyz_cv = fit(has_z & ~held, pre_cv, fac * accel_mm, n_lin=1)[2]
            r2 = ((z_in - xyz_cv[..., 2]) / zs)[held] ** 2
            scores[fac] = float(np.mean(np.minimum(r2, DEPTH_GATE ** 2)))
        factor = min(scores, key=scores.get)
    else:
        factor = z_accel_factor
    g, values, xyz, use, iters = fit(has_z, pre_z, None if factor is None else factor * accel_mm, stretch=stretch_on)
    lengths = resid = None
    if stretch_on:
        lengths = values.atVector(LENGTH_KEY)
        resid = _lengths(xyz, edges_rows) - lengths[:, None]
    t_opt = time.perf_counter() - t1
    t2 = time.perf_counter()
    frame_cov = cov = None
    if config.marginals:
        marg = gtsam.Marginals(g.graph, values)
        frame_cov = np.stack([marg.marginalCovariance(gtsam.symbol("x", t)) for t in range(f)]).astype(np.float32)
        idx = np.arange(n)
        blocks = frame_cov.reshape(f, n, 3, n, 3)[:, idx, :, idx, :]  # (n, f, 3, 3)
        cov = np.asarray(blocks, float)
    t_marg = time.perf_counter() - t2
    report = Smoother3DReport(iterations=iters, z_accel_factor=factor, z_accel_cv=scores, n_variables=f, n_factors=int(g.graph.size()),
                              n_depth=int(has_z.sum()), n_depth_dropped=int((has_z & ~use).sum()),
                              mm_per_px=float(mm_per_px), seconds_build=t_build, seconds_optimize=t_opt,
                              seconds_marginals=t_marg, stretch_rel=stretch_rel if stretch_on else None,
                              lengths_mm=None if lengths is None else tuple(float(v) for v in lengths),
                              length_rms_mm=None if resid is None else float(np.sqrt(np.mean(resid ** 2))),
                              length_rms_sigmas=None if resid is None else
                              float(np.sqrt(np.mean((resid / (stretch_rel * lengths[:, None])) ** 2))))
    return Smoothed3D(node_ids=node_ids, xyz_mm=xyz, observed=obs, depth_used=use, frame_cov=frame_cov, cov=cov,
                      report=report)
