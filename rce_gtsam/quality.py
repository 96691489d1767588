"""A quality verdict on every kappa: ``ok``, or the reasons it should not be trusted.

Each segment (bend row of the response) gets the reasons that apply, in this order, joined by ``+``:

* ``off_structure`` — (``rce run``) one of the bend's nodes was annotated where the first frames show no
  image structure or no change (:mod:`rce_gtsam.track.checks`): it is probably not on the branch.
* ``tracking_lost`` — one of the bend's three nodes was observed in fewer than ``1 - LOST_SHARE`` (half)
  of the frames: the smoother interpolated it for most of the clip. A node observed in fewer than 2 frames
  (e.g. only in the annotated first frame) is lost altogether: its bends are dropped from the fit (the run goes
  on, with one warning line naming the node; :func:`rce_gtsam.tracks.lost_nodes`), and their segments appear
  in compliance_summary.csv without a kappa, quality ``tracking_lost``, and in report.json's
  ``quality.dropped_segments``.
* ``calm_support`` — most of the excitation's variance lies in frames where one of the bend's nodes was lost:
  the share of sum_t (z_t - mean z)^2 over the frames where all three nodes were observed
  (``z_var_seen``) is below ``1 - CALM_SHARE`` (half). kappa is the ratio of the bend's motion to z's, so it
  then rests on the calm frames and says nothing about how the segment took the strong motion (a tracker
  that loses nodes in gusts gives exactly this). ``z_var_seen`` is reported for every segment.
* ``low_support`` — fewer usable (inlier, finite) frames than ``MIN_BLOCKS`` block lengths
  (2 x 25 = 50 frames at the presets' ``compliance.block_length``) or than ``SUPPORT_SHARE`` (half) of
  the clip: an all-outlier bend lands here.
* ``single_bend`` — the graph has one bend: kappa is 1 by its normalisation (geometric mean 1), nothing
  was estimated.
* ``no_signal`` — the segment's bending variance is not significantly above its noise floor. The noise
  floor is the tracking noise of the raw bending angle, estimated from the data (robust variance of the
  frame-to-frame differences of the unsmoothed angle, / 2: tracker noise is white-ish, sway is slow),
  times the smoother's variance reduction for that segment from the noise model (propagated smoothed
  angle variance / propagated raw angle variance, both from the node covariances). The test is
  an F test, since the floor is estimated too: variance / noise floor > F.ppf(1 - ALPHA, n_eff, dof) with
  n_eff = usable frames x the smoother's variance reduction (x (1 - rho1) / (1 + rho1) for AR(1) noise) and
  dof the floor's own degrees of freedom (:func:`_raw_noise`), ALPHA = 0.01.
* ``poor_fit`` — the fitted kappa * z explains less of the segment's bending than its noise allows: R^2 below
  half of the share that is signal, R^2 < ``POOR_FIT_SHARE`` x (1 - 1 / snr) (snr = bending variance /
  noise floor, see ``no_signal``), and always when R^2 < 0 (worse than the segment's own mean). Were the
  rank-1 model right, R^2 would approach 1 - 1/snr (only the noise left over); below half of that, the
  shared excitation explains less of the segment's signal than it leaves unexplained, and kappa summarises
  the minority of what the segment does (a missing effect: read the diagnosis, and kappa from the extended
  model it names). A noisy segment with a low R^2 is not flagged for it: its noise explains the low R^2.
* ``wide_ci`` — the 95 % interval is at least as wide (in log kappa) as the shrinkage prior's own 95 %
  interval, 2 x 1.96 x ``compliance.prior_sd_log``, or is not finite: the data did not narrow kappa.
* ``uninformative`` — the 95 % interval reaches below ``STIFF_BELOW`` = 2^-1/2 = 0.71 AND above
  ``COMPLIANT_ABOVE`` = 2^1/2 = 1.41: it cannot tell a stiff segment from a compliant one. kappa is relative
  to the branch's geometric mean, 1 by normalisation; "stiffer" and "more compliant than the branch" are the
  two sides of 1, and the cutoffs put a factor sqrt(2) on either side, so an interval that holds both holds
  segments a factor 2 apart in compliance with the branch's mean between them. A factor 2 is the smallest
  contrast worth a map: the geometric SD of kappa over the segments of the two real plants is 1.73 and 1.70
  (TAPIR tracks, default preset), so a factor 2 spans about one SD of what the segments of a branch differ
  by. An interval entirely on one side (e.g. [0.40, 0.80], or [1.2, 3.0]) is informative however wide; one
  inside [0.71, 1.41] says "about average", which is information too. The cutoffs are fixed numbers of the
  method (the normalisation's), not fitted to a plant; the run prints how many segments are informative.

Slow tracker drift is not in the noise floor (it looks like slow sway); ``wide_ci`` and the residual
figures are where it shows.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .bending.angles import angle_gradient

#: A node unseen in more than this share of the clip's frames is "lost" (tracking_lost; ``rce track`` warns).
LOST_SHARE = 0.5
#: Minimum usable frames, in block lengths (compliance.block_length).
MIN_BLOCKS = 2
#: Minimum share of the clip's frames with a usable bend.
SUPPORT_SHARE = 0.5
#: One-sided level of the no-signal chi-square test.
ALPHA = 0.01
#: calm_support: flagged when more than this share of the excitation's variance lies in frames where one of the
#: bend's nodes was lost (most of it: kappa then rests on the calm frames).
CALM_SHARE = 0.5
#: poor_fit: R^2 must reach this share of what the noise allows, 1 - 1/snr (half: kappa z explains at least
#: as much of the segment's signal as it leaves).
POOR_FIT_SHARE = 0.5
#: uninformative: an interval reaching below STIFF_BELOW and above COMPLIANT_ABOVE (a factor sqrt(2) either
#: side of the branch's geometric mean, 1) cannot tell a stiff segment from a compliant one.
STIFF_BELOW = 2.0 ** -0.5
COMPLIANT_ABOVE = 2.0 ** 0.5
#: z of the prior's two-sided 95 % interval (wide_ci).
Z95 = 1.959964

#: ``AnalysisResult.inputs`` key of the comma-separated node ids whose annotation is not on a textured,
#: moving structure (``rce run``'s check before tracking, :mod:`rce_gtsam.track.checks`).
OFF_STRUCTURE_KEY = "off_structure_nodes"

REASONS = ("off_structure", "tracking_lost", "calm_support", "low_support", "single_bend", "no_signal", "poor_fit",
           "wide_ci", "uninformative")


@dataclass(frozen=True)
class SegmentQuality:
    """The verdict on one segment's kappa and the numbers behind it.

    bend_var_deg2: variance of the bending deviation over usable frames (deg^2); noise_var_deg2: its
    noise floor (deg^2); snr: their ratio; snr_threshold: the ratio the chi-square test needs;
    n_frames: usable frames; min_node_visible: smallest observed share of the bend's three nodes.
    """

    edge: tuple[int, int]
    reasons: tuple[str, ...]
    bend_var_deg2: float
    noise_var_deg2: float
    snr: float
    snr_threshold: float
    n_frames: int
    min_node_visible: float
    z_var_seen: float = float("nan")
    r2: float = float("nan")
    r2_needed: float = 0.0
    informative: bool | None = None

    @property
    def quality(self) -> str:
        return "+".join(self.reasons) if self.reasons else "ok"

    @property
    def ok(self) -> bool:
        return not self.reasons


#: Asymptotic efficiency of the MAD's variance estimate relative to the sample variance's, Gaussian data
#: (2 / (pi (1.4826 x 0.6745)^2 ...) = 0.3675): a MAD over m values carries the information of 0.37 m.
MAD_EFFICIENCY = 0.3675


def _raw_noise(a: np.ndarray) -> tuple[float, float, float]:
    """(variance deg^2, lag-1 autocorrelation, degrees of freedom) of the tracking noise in an angle series
    (degrees), from its frame-to-frame differences (sway is slow, tracker noise is not): robust variance of the
    differences (MAD; wrapped to +-180 deg; a difference across a gap is dropped) / (2 (1 - rho1)), with rho1
    from the correlation c of consecutive differences (-1/2 for white noise). The degrees of freedom of that
    estimate: the m differences, times the MAD's efficiency, over 1 + 2 c^2 (consecutive differences share a
    frame, so they count less). NaN variance if fewer than 3 differences."""
    d = (np.diff(a) + 180.0) % 360.0 - 180.0
    pair = np.isfinite(d[1:]) & np.isfinite(d[:-1])
    d_ok = d[np.isfinite(d)]
    if d_ok.size < 3:
        return float("nan"), 0.0, 0.0
    mad = 1.482602 * np.median(np.abs(d_ok - np.median(d_ok)))
    rho1, c = 0.0, -0.5
    if pair.sum() >= 3 and np.std(d[1:][pair]) > 0 and np.std(d[:-1][pair]) > 0:
        c = float(np.corrcoef(d[1:][pair], d[:-1][pair])[0, 1])
        rho1 = float(np.clip((1 + 2 * c) / (2 + 2 * c), 0.0, 0.9)) if c > -0.5 else 0.0
    dof = MAD_EFFICIENCY * d_ok.size / (1.0 + 2.0 * c * c)
    return float(mad**2 / (2.0 * (1.0 - rho1))), rho1, float(dof)


def _raw_angle_variance(xy: np.ndarray, sigma2: np.ndarray, rows) -> np.ndarray:
    """(F,) first-order variance (deg^2) of the turning angle of the raw positions, nodes independent with
    isotropic variances ``sigma2`` (N, F) px^2."""
    g = angle_gradient(*(xy[i] for i in rows))  # (F, 6) rad / px
    var = sum(sigma2[i] * (g[:, 2 * a] ** 2 + g[:, 2 * a + 1] ** 2) for a, i in enumerate(rows))
    return var * np.degrees(1.0) ** 2


def _r2(y: np.ndarray, pred: np.ndarray) -> float:
    ok = np.isfinite(y) & np.isfinite(pred)
    if ok.sum() < 2:
        return float("nan")
    ss_tot = float(np.sum((y[ok] - y[ok].mean()) ** 2))
    return float(1 - np.sum((y[ok] - pred[ok]) ** 2) / ss_tot) if ss_tot > 1e-12 else float("nan")


def assess_quality(result) -> dict[tuple[int, int], SegmentQuality]:
    """The verdict on every segment of an :class:`~rce_gtsam.pipeline.AnalysisResult` (see module docstring)."""
    from scipy.special import fdtri  # f.ppf(q, k1, k2) = fdtri(k1, k2, q), without importing scipy.stats (~0.8 s)

    resp, bending, preset = result.response, result.bending, result.preset
    cfg = preset.compliance
    tracks = result.tracks
    n_clip = tracks.n_frames
    visible = tracks.observed.mean(axis=1)
    row = {int(n): i for i, n in enumerate(tracks.node_ids)}
    raw_xy = tracks.xy
    if tracks.sigma_px is not None:
        sigma2 = tracks.sigma_px**2
    else:
        sigma2 = np.full(tracks.observed.shape, 1.0 / preset.smoother.measurement_weight)
    pred = result.fit.predict()
    off = {int(n) for n in str(result.inputs.get(OFF_STRUCTURE_KEY, "")).split(",") if n.strip()}
    n_segments = len(resp.edges)
    zc = np.asarray(result.fit.z, dtype=float)
    zc = np.where(np.isfinite(zc), zc - np.nanmean(zc) if np.isfinite(zc).any() else 0.0, 0.0)
    z_power = zc**2
    seen_frames = tracks.observed[:, resp.frames]  # (N, T): each node observed at the response's frames
    out = {}
    for i, edge in enumerate(resp.edges):
        k = int(resp.bend_rows[i])
        bend = bending.bends[k]
        rows = [row[n] for n in bend.nodes]
        use = bending.inlier[k] & np.isfinite(bending.delta_deg[k])
        n = int(use.sum())
        d = bending.delta_deg[k][use]
        var = float(np.var(d)) if n >= 2 else 0.0
        raw_noise, rho1, noise_dof = _raw_noise(_turning(raw_xy, rows))
        reduction = float("nan")
        if bending.variance_deg2 is not None and n:
            v_raw = _raw_angle_variance(raw_xy, sigma2, rows)[use]
            v_s = bending.variance_deg2[k][use]
            good = np.isfinite(v_raw) & np.isfinite(v_s) & (v_raw > 0)
            if good.any():
                reduction = float(np.mean(v_s[good]) / np.mean(v_raw[good]))
        if not np.isfinite(reduction):  # no propagated variances: the raw noise is the (conservative) floor
            reduction = 1.0
        noise = raw_noise * reduction if np.isfinite(raw_noise) else float("nan")
        if var <= 1e-12:
            snr = 0.0
        elif not noise > 0:
            snr = float("inf") if noise == 0 else float("nan")
        else:
            snr = var / noise
        # white noise through a linear smoother of unit DC gain: correlation time = 1 / variance reduction;
        # an AR(1) input multiplies it by (1 + rho1) / (1 - rho1)
        n_eff = max(n * min(reduction, 1.0) * (1 - rho1) / (1 + rho1), 1.0)
        # both variances are estimates: their ratio is F(n_eff, noise_dof) distributed under "no signal". The
        # chi-square threshold (the floor taken as known) let static branches through: 120 frames, 4 nodes,
        # no smoothing, a floor 26 % below the (pure-noise) bend variance, from 119 differences -> ratio 1.36
        # against 1.32, "ok"
        threshold = float(fdtri(n_eff, max(noise_dof, 1.0), 1.0 - ALPHA))
        reasons = ["off_structure"] if off & set(bend.nodes) else []
        node_vis = float(min(visible[r] for r in rows))
        if node_vis < 1 - LOST_SHARE:
            reasons.append("tracking_lost")
        seen = seen_frames[rows].all(axis=0)
        z_seen = float(z_power[seen].sum() / z_power.sum()) if z_power.sum() > 0 else float("nan")
        if z_seen < 1 - CALM_SHARE:
            reasons.append("calm_support")
        if n < MIN_BLOCKS * cfg.block_length or n < SUPPORT_SHARE * n_clip:
            reasons.append("low_support")
        if n_segments == 1:
            reasons.append("single_bend")
        if not snr > threshold:
            reasons.append("no_signal")
        r2 = _r2(resp.Y[i], pred[i])
        r2_needed = POOR_FIT_SHARE * (1.0 - 1.0 / snr) if np.isfinite(snr) and snr > 1 else 0.0
        if not r2 >= r2_needed:
            reasons.append("poor_fit")
        interval = _interval(result.ci, i)
        if _wide(interval, cfg):
            reasons.append("wide_ci")
        informative = _informative(interval)
        if informative is False:
            reasons.append("uninformative")
        out[edge] = SegmentQuality(edge=edge, reasons=tuple(reasons), bend_var_deg2=var, noise_var_deg2=noise,
                                   snr=snr, snr_threshold=threshold, n_frames=n, min_node_visible=node_vis,
                                   z_var_seen=z_seen, r2=r2, r2_needed=r2_needed, informative=informative)
    return out


def _turning(xy: np.ndarray, rows) -> np.ndarray:
    from .bending.angles import bend_angles
    return bend_angles(xy[rows[0]], xy[rows[1]], xy[rows[2]], True)


def _interval(ci, i: int) -> tuple[float, float] | None:
    """Segment ``i``'s 95 % interval (low, high) of a :class:`~rce_gtsam.model.uncertainty.BootstrapCI`, None
    without one (no bootstrap)."""
    if ci is None:
        return None
    return float(ci.low[i]), float(ci.high[i])


def _wide(interval: tuple[float, float] | None, cfg) -> bool:
    """``wide_ci``: the interval is at least as wide (log kappa) as the shrinkage prior's own 95 % interval."""
    if interval is None:
        return False  # no bootstrap: no interval to judge
    lo, hi = interval
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo <= 0:
        return True
    return bool(np.log(hi / lo) >= 2 * Z95 * cfg.prior_sd_log)


def _informative(interval: tuple[float, float] | None) -> bool | None:
    """Whether a 95 % interval tells stiff from compliant (see ``uninformative``); None without an interval (no
    bootstrap)."""
    if interval is None:
        return None
    lo, hi = interval
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return False
    return not (lo < STIFF_BELOW and hi > COMPLIANT_ABOVE)


#: The reasons that judge the data behind a segment, not the model fitted to it: they hold for the κ of any model
#: fitted to the same bends (the rank-1 κ and that of the model with a named effect).
DATA_REASONS = ("off_structure", "tracking_lost", "calm_support", "low_support", "single_bend", "no_signal")


def assess_reported_quality(result, rank1: dict | None = None) -> dict[tuple[int, int], SegmentQuality]:
    """The verdict on every segment's κ *to report* (``result.kappa_choice``; see :mod:`rce_gtsam.kappa_report`).

    Without a fitted named effect that κ is the rank-1 κ, and this is :func:`assess_quality`. With one, the data's
    reasons (:data:`DATA_REASONS`) are the rank-1 verdict's (``rank1``, computed when None), and the model's are
    judged again on the model with the effect: ``poor_fit`` from the R^2 of its prediction (same rule and noise
    floor; the rank-1 flag where the choice carries no prediction), ``wide_ci`` and ``uninformative`` from its own
    95 % interval."""
    rank1 = assess_quality(result) if rank1 is None else rank1
    choice = getattr(result, "kappa_choice", None)
    if choice is None or not choice.fitted:
        return rank1

    at = {tuple(e): i for i, e in enumerate(choice.edges)}
    has_ci = choice.ci_low is not None and choice.ci_high is not None
    cfg = result.preset.compliance
    out = {}
    for r, (edge, q) in enumerate(rank1.items()):
        i = at.get(tuple(edge))
        reasons = [x for x in q.reasons if x in DATA_REASONS]
        r2, informative = float("nan"), None
        if i is None or not np.isfinite(choice.kappa[i]):
            reasons.append("poor_fit")
        else:
            if choice.prediction is not None:
                r2 = _r2(result.response.Y[r], choice.prediction[i])
                if not r2 >= q.r2_needed:
                    reasons.append("poor_fit")
            elif "poor_fit" in q.reasons:  # no prediction to judge the model with the effect by: keep the rank-1 flag
                reasons.append("poor_fit")
            interval = (float(choice.ci_low[i]), float(choice.ci_high[i])) if has_ci else None
            if _wide(interval, cfg):
                reasons.append("wide_ci")
            informative = _informative(interval)
            if informative is False:
                reasons.append("uninformative")
        out[edge] = dataclasses.replace(q, reasons=tuple(x for x in REASONS if x in reasons), r2=r2,
                                        informative=informative)
    return out


def informative_line(qualities: dict) -> str | None:
    """"14 of 23 segments informative (95 % CI not reaching both below 0.71 and above 1.41)", or None
    without intervals."""
    judged = [q.informative for q in qualities.values() if q.informative is not None]
    if not judged:
        return None
    return (f"{sum(judged)} of {len(qualities)} segments informative (95 % CI does not reach both below "
            f"{STIFF_BELOW:.2f} and above {COMPLIANT_ABOVE:.2f}: it tells stiff from compliant)")


def verdict_line(qualities: dict) -> str | None:
    """None when at least one segment is ``ok``; otherwise one line saying why no kappa can be trusted."""
    if any(q.ok for q in qualities.values()):
        return None
    n = len(qualities)
    counts = {r: sum(r in q.reasons for q in qualities.values()) for r in REASONS}
    if n and counts["single_bend"] == n:
        head = "the graph has a single bend, so kappa is 1 by its normalisation and nothing was estimated"
    elif n and counts["low_support"] == n:
        head = "no segment has enough usable frames"
    elif n and counts["no_signal"] == n:
        head = "no motion above the noise floor in any segment"
    else:
        head = "no segment's kappa passes the quality checks"
    detail = ", ".join(f"{r} {c}" for r, c in counts.items() if c)
    return f"{head} ({detail} of {n} segments); the outputs are written for inspection"


def quality_report(result, qualities: dict | None = None) -> dict:
    """The ``quality`` section of report.json: the rules' constants and each segment's numbers."""
    qualities = assess_quality(result) if qualities is None else qualities
    cfg = result.preset.compliance
    return {
        "rules": {"lost_share": LOST_SHARE, "min_frames": MIN_BLOCKS * cfg.block_length,
                  "support_share": SUPPORT_SHARE, "no_signal_alpha": ALPHA,
                  "wide_ci_log_width": 2 * Z95 * cfg.prior_sd_log,
                  "poor_fit_r2_below": f"max(0, {POOR_FIT_SHARE} x (1 - 1/snr))",
                  "calm_support_z_var_seen_below": 1 - CALM_SHARE,
                  "uninformative_ci_below_and_above": [STIFF_BELOW, COMPLIANT_ABOVE]},
        "n_ok": sum(q.ok for q in qualities.values()),
        "n_informative": sum(q.informative is True for q in qualities.values()),
        "n_segments": len(qualities),
        "segments": {f"{j}->{c}": {"quality": q.quality, "bend_var_deg2": q.bend_var_deg2,
                                   "noise_var_deg2": q.noise_var_deg2, "snr": q.snr,
                                   "snr_threshold": q.snr_threshold, "n_frames": q.n_frames,
                                   "min_node_visible": q.min_node_visible, "z_var_seen": q.z_var_seen,
                                   "r2": q.r2, "r2_needed": q.r2_needed, "informative": q.informative}
                     for (j, c), q in qualities.items()},
        "verdict": verdict_line(qualities),
        **_dropped(result),
    }


def _dropped(result) -> dict:
    """The lost nodes (observed in fewer than 2 frames) and the segments dropped with them, for report.json."""
    from .tracks import dropped_edges, lost_nodes
    lost = lost_nodes(result.tracks)
    return {"lost_nodes": list(lost),
            "dropped_segments": {f"{j}->{c}": "tracking_lost" for j, c in dropped_edges(result.graph, lost)}}
