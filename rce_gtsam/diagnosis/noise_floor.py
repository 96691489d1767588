"""The angle-noise floor, estimated without the rank-1 model: how much of the bending is tracking noise?

A bend angle at joint j is computed from three tracked nodes (grandparent g, joint j, child c). Small position
errors *across* the branch turn it by

    d theta_j = n_c / L2 - n_j (1 / L1 + 1 / L2) + n_g / L1        (radians; L1 = |g j|, L2 = |j c| in px)

where n_i is node i's error perpendicular to the branch. Errors *along* the branch (u_i) leave the angle alone
but stretch the segments — and a branch segment does not stretch. So the same combination of *relative length
changes* of the two segments,

    d_j(t) = dL_(j,c)(t) / L2 - dL_(g,j)(t) / L1 = u_c / L2 - u_j (1 / L1 + 1 / L2) + u_g / L1,

is a model-free record of the along-branch tracking error that survived smoothing, with the same geometry,
spectrum and correlation between neighbouring bends as the angle noise. (A uniform out-of-plane tilt that
foreshortens both segments alike cancels in d_j.) Trackers slide along a featureless stem more than across
it; the across/along variance ratio q is measured from the highest frequencies of the *raw* tracks (4th
differences: < 0.2 % of the power of motion below 1 Hz at 30 fps, 70x the variance of white noise; a robust
scale ignores jumps). Then

    inextensibility estimate of row j:  var(noise_j) = q var(d_j)          (converted to deg^2)

A second, smaller estimate needs no inextensibility: the *white* part of the raw angle noise (4th differences
of the raw bend angles) passed through the smoother's transfer function — a lower bound, because slow drift
is invisible at high frequencies.

Which one is used, per row: the inextensibility estimate, unless it exceeds the row's whole bending variance
(or its spectrum exceeds the bending's own in any frequency band, :func:`spectrum_below`) by more than its
sampling error allows (then the segments stretch by more than across-branch tracking noise
could — out-of-plane swing, or a tracker sliding along the stem at low frequency — and the row falls back to
the white lower bound, flagged). On 20 branches of the project's simulator (noise settings varied over seeds)
the estimate is 0.84-1.10 of the true angle-noise RMS, median 0.95 (``benchmarks/bench_noise_floor.py``;
checked by ``tests/test_noise_floor.py``); the variance budget's floor, which keeps the lower bound on
flagged rows, is 0.53-1.01 of the true noise variance, and carries that accuracy into its SE
(:data:`~.budget.FLOOR_REL_SD`).

Units: px for positions, degrees for angles, frames for time, cycles/frame for frequency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: variance of the 4th difference of unit white noise: sum of squared binomial(4) coefficients
D4_GAIN = 70.0
#: MAD -> standard deviation for a normal distribution
MAD_SD = 1.4826


@dataclass(frozen=True, eq=False)
class NoiseFloor:
    """Model-free angle-noise estimate for the rows of a response matrix (degrees).

    variance_deg2: (E,) the point estimate of each row's angle-noise variance (deg^2): the inextensibility
        estimate where it holds (``valid``); elsewhere the white-noise lower bound times the median full / white
        ratio of the valid rows (the drift a tracker adds to its white noise is a property of the tracker and
        the footage, not of one segment), capped at the row's own stretch estimate and bending variance. The
        variance budget uses ``white_deg2`` on those rows (the floor there is only bounded).
    inextensible_deg2: (E,) q var(d_j): the inextensibility estimate (deg^2).
    white_deg2: (E,) the white part of the raw angle noise after smoothing: a lower bound (deg^2).
    valid: (E,) bool — the inextensibility estimate is consistent with the row's bending variance; False rows
        use ``white_deg2`` (a lower bound) instead.
    across_over_along: q, across/along variance ratio of node errors at high frequency (1 = isotropic).
    smoother_gain: fraction of white-noise variance the smoother passes (0..1).
    series_deg: (E, T) sqrt(q) d_j(t) in degrees — a realisation with the noise's spectrum and its correlation
        between rows (NaN where a length is missing); surrogates phase-randomise it.
    n_eff: (E,) effective number of independent samples of each row's d_j (for standard errors).
    coherent_share: (E,) share of var(d_j) explained by the motion of bends sharing no node with j (0 for pure
        tracking noise up to ~2 / n_eff by chance).
    nodewise_deg2: (E,) the node-wise estimate from the rank-1 residual's covariance between bends that share a
        node (:mod:`.noise_floor_nodewise`; NaN = not estimable, None = not computed); ``variance_deg2`` is at
        least this where it is finite. nodewise_sigma_px: the node error's SD across the branch it implies (px).
    """

    variance_deg2: np.ndarray
    inextensible_deg2: np.ndarray
    white_deg2: np.ndarray
    valid: np.ndarray
    across_over_along: float
    smoother_gain: float
    series_deg: np.ndarray
    n_eff: np.ndarray
    coherent_share: np.ndarray
    nodewise_deg2: np.ndarray | None = None
    nodewise_sigma_px: float = float("nan")

    @property
    def rms_deg(self) -> float:
        """Overall RMS angle noise over rows (deg)."""
        return float(math.sqrt(np.mean(self.variance_deg2))) if len(self.variance_deg2) else float("nan")

    def as_dict(self) -> dict:
        return {"rms_deg": self.rms_deg,
                "per_row_deg2": self.variance_deg2.tolist(),
                "inextensible_deg2": self.inextensible_deg2.tolist(),
                "white_lower_bound_deg2": self.white_deg2.tolist(),
                "inextensibility_holds": [bool(v) for v in self.valid],
                "across_over_along": float(self.across_over_along),
                "nodewise_deg2": None if self.nodewise_deg2 is None else
                [None if not np.isfinite(v) else float(v) for v in self.nodewise_deg2],
                "nodewise_sigma_px": None if not np.isfinite(self.nodewise_sigma_px) else float(self.nodewise_sigma_px),
                "smoother_white_gain": float(self.smoother_gain),
                "method": "q x var(relative stretch of the two segments) of the smoothed tracks (inextensibility); "
                          "rows where that exceeds the bending variance use the white-noise lower bound; raised "
                          "to the node-wise estimate (the rank-1 residual's covariance between bends that share "
                          "a node) where that is larger"}


def rest_frame(xy: np.ndarray, node_ids, edges) -> tuple[np.ndarray, dict]:
    """(N, 2) unit branch tangent per node at the median pose, and {edge: rest length px}."""
    row = {int(n): i for i, n in enumerate(node_ids)}
    rest = np.nanmedian(xy, axis=1)  # (N, 2)
    tan = np.zeros_like(rest)
    lengths = {}
    for p, c in edges:
        d = rest[row[c]] - rest[row[p]]
        L = float(np.hypot(*d))
        lengths[(p, c)] = L
        if L > 0:
            tan[row[c]] += d / L
            tan[row[p]] += d / L
    norm = np.linalg.norm(tan, axis=1, keepdims=True)
    return tan / np.maximum(norm, 1e-12), lengths


def robust_sd(x: np.ndarray) -> float:
    """MAD-based standard deviation of the finite values of x (0 if none)."""
    x = x[np.isfinite(x)]
    return float(MAD_SD * np.median(np.abs(x - np.median(x)))) if x.size else 0.0


def frame_tangents(xy: np.ndarray, node_ids, edges) -> np.ndarray:
    """(N, F, 2) unit branch direction at each node and frame (sum of its segments' unit directions; NaN where
    a neighbour is missing)."""
    row = {int(n): i for i, n in enumerate(node_ids)}
    tan = np.zeros_like(xy)
    for p, c in edges:
        d = xy[row[c]] - xy[row[p]]
        d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
        tan[row[c]] += d
        tan[row[p]] += d
    return tan / np.maximum(np.linalg.norm(tan, axis=-1, keepdims=True), 1e-12)


def across_along_ratio(raw_xy: np.ndarray, tangent: np.ndarray) -> float:
    """q = var(across) / var(along) of node errors, from 4th differences of the raw tracks (robust, pooled as
    the median of per-node ratios; 1.0 when no node has 20 usable 4th differences).

    tangent: (N, 2) one direction per node, or (N, F, 2) per frame — better: a branch that sways +-10 deg
    turns a fixed direction far enough that along-branch noise (often 2-3x the across noise) leaks into the
    across component. The 4th difference passes < 0.2 % of the power of motion below 1 Hz at 30 fps and 70x
    the variance of white noise; a robust scale (MAD) ignores jumps."""
    ratios = []
    for i in range(raw_xy.shape[0]):
        d4 = np.diff(raw_xy[i], n=4, axis=0)
        t = tangent[i] if tangent.ndim == 2 else tangent[i, 2:-2]  # the stencil's centre frame
        t = np.broadcast_to(t, d4.shape)
        ok = np.isfinite(d4).all(axis=1) & np.isfinite(t).all(axis=1)
        if ok.sum() < 20:
            continue
        a = np.sum(d4[ok] * t[ok], axis=1)
        c = d4[ok, 1] * t[ok, 0] - d4[ok, 0] * t[ok, 1]
        sa, sc = robust_sd(a), robust_sd(c)
        if sa > 0 and sc > 0:
            ratios.append((sc / sa) ** 2)
    return float(np.median(ratios)) if ratios else 1.0


def smoother_response(f: np.ndarray, presmooth_window: int, measurement_weight: float, velocity_weight: float,
                      acceleration_weight: float) -> np.ndarray:
    """The smoother's gain |H(f)| per coordinate at frequencies ``f`` (cycles/frame, 0..0.5).

    The smoother minimises w_m sum (x - y)^2 + w_v sum (dx)^2 + w_a sum (d2x)^2 (after an optional centred
    moving average), a linear time-invariant filter away from the ends with
    H(f) = MA(f) w_m / (w_m + w_v |1 - e^(-i w)|^2 + w_a |1 - e^(-i w)|^4). The edge prior (paper preset) is
    ignored: it couples nodes, not frames."""
    f = np.asarray(f, float)
    d2 = np.abs(1 - np.exp(-2j * np.pi * f)) ** 2
    H = measurement_weight / (measurement_weight + velocity_weight * d2 + acceleration_weight * d2 ** 2)
    if presmooth_window and presmooth_window > 1:
        n = int(presmooth_window)
        w = 2 * np.pi * f
        with np.errstate(invalid="ignore", divide="ignore"):
            ma = np.abs(np.sin(n * w / 2) / (n * np.sin(w / 2)))
        H = H * np.where(f == 0, 1.0, ma)
    return H


def smoother_white_gain(presmooth_window: int, measurement_weight: float, velocity_weight: float,
                        acceleration_weight: float, n_freq: int = 4096) -> float:
    """Share of a white input's variance that the smoother passes (0..1), per coordinate: the mean of
    |H(f)|^2 over frequency (:func:`smoother_response`)."""
    f = (np.arange(n_freq) + 0.5) / (2 * n_freq)  # (0, 0.5) cycles/frame
    H = smoother_response(f, presmooth_window, measurement_weight, velocity_weight, acceleration_weight)
    return float(np.mean(H ** 2))


def stretch_bends(xy: np.ndarray, node_ids, bends, lengths: dict) -> np.ndarray:
    """(E, F) d_j(t) in radians: relative length change of (j, c) minus that of (g, j), per bend."""
    row = {int(n): i for i, n in enumerate(node_ids)}

    def rel(p, c):
        d = xy[row[c]] - xy[row[p]]
        L = np.hypot(d[:, 0], d[:, 1])
        return (L - np.nanmedian(L)) / max(lengths[(p, c)], 1e-9)

    return np.array([rel(j, c) - rel(g, j) for g, j, c in bends]).reshape(len(bends), xy.shape[1])


def effective_samples(x: np.ndarray) -> float:
    """n (1 - rho) / (1 + rho) for the lag-1 autocorrelation rho (clipped to [0, 0.99]) of the finite x."""
    ok = np.isfinite(x)
    n = int(ok.sum())
    if n < 4:
        return float(max(n, 1))
    a, b = x[:-1], x[1:]
    m = np.isfinite(a) & np.isfinite(b)
    a, b = a[m] - a[m].mean(), b[m] - b[m].mean()
    rho = float(np.sum(a * b) / max(math.sqrt(np.sum(a * a) * np.sum(b * b)), 1e-300))
    rho = min(max(rho, 0.0), 0.99)
    return n * (1 - rho) / (1 + rho)


def incoherent_part(D: np.ndarray, Y: np.ndarray, shared: np.ndarray, n_components: int = 2) -> np.ndarray:
    """(E, T) each row of D minus its least-squares projection on the top ``n_components`` principal
    components of the rows (of D and Y) that share no tracked node with it (NaN kept).

    Independent node errors cannot be predicted from bends they do not enter; whatever of d_j moves with the
    rest of the branch (an out-of-plane swing that stretches segments with the wind, a tracker that slides
    with the motion) is physical or motion-locked and is not counted as noise. A few components only, so the
    projection removes at most a few of the n_eff independent samples (its loss is corrected for)."""
    E, T = D.shape
    out = np.full_like(D, np.nan)
    Dz = np.where(np.isfinite(D), D - np.nanmean(D, axis=1, keepdims=True), 0.0)
    Yz = np.where(np.isfinite(Y), Y - np.nanmean(Y, axis=1, keepdims=True), 0.0)
    for e in range(E):
        far = ~shared[e]
        ok = np.isfinite(D[e])
        if far.sum() < 1 or ok.sum() < 4 * n_components + 4:
            out[e] = D[e]
            continue
        M = np.concatenate([Dz[far], Yz[far]])
        M = M / np.maximum(np.sqrt(np.mean(M ** 2, axis=1, keepdims=True)), 1e-12)
        _, _, Vt = np.linalg.svd(M, full_matrices=False)
        X = Vt[:n_components].T[ok]
        beta, *_ = np.linalg.lstsq(X, Dz[e, ok], rcond=None)
        out[e, ok] = Dz[e, ok] - X @ beta
    return out


def spectrum_below(D: np.ndarray, Y: np.ndarray, z_crit: float = 2.0, n_bands: int = 4,
                   nperseg: int = 64) -> np.ndarray:
    """(E,) bool: each row's noise spectrum (of D) stays below the bending's own spectrum (of Y) in every one of
    ``n_bands`` equal frequency bands, up to the sampling error of Welch estimates.

    Noise independent of the motion cannot carry more power than the measured bending at any frequency
    (S_Y = S_signal + S_noise >= S_noise). Many frequency bins make this a strict check where a variance
    comparison has few effective samples: at high frequency the bending is nearly all noise, so an
    inextensibility estimate that overshoots there (a tracker sliding along the stem, which leaves the angle
    alone) is caught. Band sums of K-segment Welch estimates over m bins (about m / 2 independent with a Hann
    window) have a relative SE ~ sqrt(2 / (K m));
    a band fails when the noise exceeds the bending by more than z_crit (Bonferroni over bands) of that for
    both estimates together."""
    from scipy import signal

    E, T = Y.shape
    n = int(max(16, min(nperseg, T // 4)))
    K = max(1, 2 * T // n - 1)

    def psd(X):
        Xf = np.where(np.isfinite(X), X - np.nanmean(X, axis=1, keepdims=True), 0.0)
        return signal.welch(Xf, nperseg=n, axis=1)[1][:, 1:]  # drop the mean bin

    Pd, Py = psd(D), psd(Y)
    edges = np.linspace(0, Pd.shape[1], n_bands + 1).round().astype(int)
    z = z_crit + 0.5 * math.log(n_bands)  # ~Bonferroni over the bands
    ok = np.ones(E, bool)
    for a, b in zip(edges[:-1], edges[1:]):
        m = max(b - a, 1)
        sd, sy = Pd[:, a:b].sum(axis=1), Py[:, a:b].sum(axis=1)
        # neighbouring bins of a Hann-windowed Welch estimate are correlated: count m / 2 independent ones
        ok &= sd <= sy * (1.0 + z * math.sqrt(2.0 / (K * max(m / 2.0, 1.0))))
    return ok


def estimate_noise_floor(raw_xy: np.ndarray, smoothed_xy: np.ndarray, node_ids, edges, bends,
                         Y: np.ndarray, frames: np.ndarray, raw_angle_deg: np.ndarray,
                         smoother_gain: float, shared: np.ndarray | None = None,
                         z_crit: float = 2.0) -> NoiseFloor:
    """Estimate the angle-noise floor of each response row without any model of the bending.

    raw_xy: (N, F, 2) tracker positions (px, NaN = not observed); smoothed_xy: (N, F, 2) smoothed positions at
    observed frames (NaN elsewhere); node_ids: (N,); edges: (parent, child) pairs of the graph; bends:
    (grandparent, joint, child) per response row; Y: (E, T) the response (deg, NaN = missing/outlier);
    frames: (T,) video frame of each column; raw_angle_deg: (E, F) the bend angles of the raw tracks;
    smoother_gain: :func:`smoother_white_gain` of the preset; shared: (E, E) bool, rows whose bends share a
    tracked node (default: rows up to two apart); the part of d_j coherent with rows that share no node
    with j is removed (:func:`incoherent_part`); z_crit: how many standard errors the
    inextensibility estimate may exceed the row's bending variance before it is rejected.
    """
    node_ids = [int(n) for n in node_ids]
    tangent, lengths = rest_frame(smoothed_xy, node_ids, edges)
    # per-frame directions from the smoothed positions (filled over gaps with the rest direction)
    tan_t = frame_tangents(smoothed_xy, node_ids, edges)
    tan_t = np.where(np.isfinite(tan_t), tan_t, tangent[:, None, :])
    q = across_along_ratio(raw_xy, tan_t)
    D = np.degrees(stretch_bends(smoothed_xy, node_ids, bends, lengths))[:, frames] * math.sqrt(q)
    D = np.where(np.isfinite(Y), D, np.nan)
    E = Y.shape[0]
    if shared is None:
        idx = np.arange(E)
        shared = np.abs(idx[:, None] - idx[None, :]) <= 2
    D_inc = incoherent_part(D, Y, shared)
    inext = np.zeros(E)
    n_eff = np.ones(E)
    coherent = np.zeros(E)
    total = np.zeros(E)
    white = np.zeros(E)
    se_total = np.zeros(E)
    for e in range(E):
        d = D[e][np.isfinite(D[e])]
        inext[e] = float(np.mean((d - d.mean()) ** 2)) if d.size > 1 else np.nan
        di = D_inc[e][np.isfinite(D_inc[e])]
        coherent[e] = 1.0 - float(np.mean(di ** 2)) / inext[e] if d.size > 1 and inext[e] > 0 else 0.0
        n_eff[e] = effective_samples(D[e])
        y = Y[e][np.isfinite(Y[e])]
        total[e] = float(np.mean(y ** 2)) if y.size else np.nan
        se_total[e] = math.sqrt(2.0 / max(effective_samples(Y[e]), 1.0))
        white[e] = (robust_sd(np.diff(raw_angle_deg[e], n=4)) ** 2 / D4_GAIN) * smoother_gain
    # independent node errors share no variance with bends they do not enter: the share explained by the
    # far rows' 2 components is ~2 / n_eff by chance (its SE ~ the same); more means the segments stretch with
    # the branch's motion (out of plane, or a tracker sliding with the motion), not by tracking noise
    chance = 2.0 / np.maximum(n_eff, 1.0)
    incoherent_ok = coherent <= chance + z_crit * chance
    spectral_ok = spectrum_below(D, Y, z_crit)
    valid = np.isfinite(inext) & incoherent_ok & spectral_ok & (inext <= total * (1.0 + z_crit * se_total))
    # point estimate where inextensibility fails: the white-noise lower bound misses drift, so scale it by the
    # full / white ratio of the rows where the estimate holds (how much drift a tracker adds to its white noise
    # is a property of the tracker and the footage, not of one segment), capped by what the row's own stretch
    # and bending allow; the variance budget keeps the plain lower bound on these rows (they stay "bounded")
    ratio = inext[valid] / np.maximum(white[valid], 1e-300)
    drift_factor = float(np.median(ratio)) if valid.sum() >= 3 else 1.0
    cap = np.minimum(np.where(np.isfinite(inext), inext, np.inf), np.where(np.isfinite(total), total, np.inf))
    transferred = np.clip(white * max(drift_factor, 1.0), white, np.maximum(cap, white))
    var = np.where(valid, inext, transferred)
    return NoiseFloor(variance_deg2=var, inextensible_deg2=inext, white_deg2=white, valid=valid,
                      across_over_along=q, smoother_gain=smoother_gain, series_deg=D, n_eff=n_eff,
                      coherent_share=coherent)


def smoother_weights(result) -> tuple[int, float, float, float]:
    """(presmooth window, w_m, w_v, w_a) of ``result``'s smoother as :func:`smoother_response` takes them: w_m
    from the tracks' median sigma_px where they carry one (1 / sigma^2), else the preset's."""
    sm = result.preset.smoother
    w_m = sm.measurement_weight
    sig = result.tracks.sigma_px
    if sig is not None and np.isfinite(sig).any():
        w_m = float(np.nanmedian(1.0 / np.asarray(sig)[np.isfinite(sig)] ** 2))
    return sm.presmooth_window, w_m, sm.velocity_weight, sm.acceleration_weight


def noise_floor_of(result) -> NoiseFloor:
    """:func:`estimate_noise_floor` of an :class:`~rce_gtsam.pipeline.AnalysisResult` (its response rows)."""
    r = result.response
    gain = smoother_white_gain(*smoother_weights(result))
    bends = [result.bending.bends[k] for k in r.bend_rows]
    raw_angle = result.raw_bending.angle_deg[r.bend_rows]
    nodes = [frozenset((b.grandparent, b.joint, b.child)) for b in bends]
    shared = np.array([[bool(a & b) for b in nodes] for a in nodes])
    smoothed_xy = result.smoothed.tracks.xy.copy()
    smoothed_xy[~result.smoothed.observed] = np.nan  # the frames a tracker saw, as the bends use them
    triples = [(b.grandparent, b.joint, b.child) for b in bends]
    nf = estimate_noise_floor(result.tracks.xy, smoothed_xy, result.tracks.node_ids, result.graph.edges, triples,
                              r.Y, r.frames, raw_angle, gain, shared=shared)
    return with_nodewise(nf, nodewise_of(result, triples))


def nodewise_of(result, triples):
    """:func:`~.noise_floor_nodewise.nodewise_floor` of ``result``'s rank-1 fit (None without one)."""
    from .noise_floor_nodewise import nodewise_floor
    fit = getattr(result, "fit", None)
    if fit is None or getattr(fit, "z", None) is None:
        return None
    r = result.response
    kappa = np.asarray(fit.kappa, float) * np.asarray(getattr(fit, "direction", 1.0), float)
    return nodewise_floor(r.Y - fit.predict(), kappa, triples, rest_positions(result, triples), z=fit.z)


def rest_positions(result, triples) -> dict:
    """{node id: (2,) px} the rest position (median smoothed position) of every node of the bends ``triples``."""
    row = {int(n): i for i, n in enumerate(result.tracks.node_ids)}
    rest = np.nanmedian(result.smoothed.tracks.xy, axis=1)
    return {n: rest[row[n]] for t in triples for n in t}


def with_nodewise(nf: NoiseFloor, nodewise) -> NoiseFloor:
    """``nf`` with the node-wise estimate attached and its per-row variance raised to it where it is larger."""
    if nodewise is None:
        return nf
    from dataclasses import replace
    nw = np.asarray(nodewise.variance_deg2, float)
    return replace(nf, variance_deg2=np.fmax(nf.variance_deg2, nw), nodewise_deg2=nw,
                   nodewise_sigma_px=nodewise.sigma_px)
