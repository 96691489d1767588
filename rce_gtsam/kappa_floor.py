"""What limits kappa on a given video: the accuracy a tracker error of e px allows on this branch and this motion.

A node's error across the branch, n (px), turns the bends it takes part in by the geometry alone,

    d theta_j = n_c / L2 - n_j (1 / L1 + 1 / L2) + n_g / L1        (radians; L1, L2 the bend's segments, px),

so a tracker good to e px gives bend j an angle noise of e * sqrt((A A')_jj) degrees
(:func:`~rce_gtsam.diagnosis.noise_floor_nodewise.angle_sensitivity`): about 2.4 e / L rad on an even chain. kappa
has to be read from the bending against that noise. How well it can be read depends on more than the ratio: the
excitation z is estimated from the same noisy bends, the shrinkage pulls poorly determined kappa toward the
prior, and neighbouring bends share a node's error. So the floor is not a formula but a simulation of exactly
that: the fitted bending kappa_e z_t, plus white node errors of e px passed through the smoother's frequency
response and through A, fitted again with the recording's own weights and settings; the RMS error of log kappa over
the draws, against the simulated branch's kappa, is the floor (:class:`KappaFloor`). It is what a
tracker whose error is e px and *independent from frame to frame* would allow; an error that follows the motion
(blur, slide along the stem) costs more, and no number of frames averages it out.

How good a guide it is (record ``kappa_floor``): under white node error on the simulator, the floor's e is within
3 % of the true error and kappa's measured log-RMSE within a factor 1.5 of the floor on 65-90 % of recordings while
the angle noise stays below the bending on most segments. Where the noise exceeds the bending on most segments,
kappa rests mostly on the prior and the data cannot show how uneven the branch really is: there the measured error
was 0.71x (simulator, 1 px) to 1.96x (texture bed, white noise) the floor (medians), and the printed line says so.

Where e comes from: the node-wise noise floor (:mod:`rce_gtsam.diagnosis.noise_floor_nodewise`): the node error
across the branch that the covariance between the rank-1 residuals of bends sharing a node implies. That is the
error after smoothing; e, the tracker's, is larger by 1 / sqrt(the smoother's white gain). Measured
against known truth in ``benchmarks/bench_kappa_floor.py`` (record ``kappa_floor``).

Reading it: the floor scales with e / (L x bending); halving it takes half the node error, twice the segment
length in pixels (zoom in, or move the camera closer) or twice the bending (stronger wind, a longer recording
with more gusts).

Units: px (node error, segment lengths), deg (angle noise, bending), kappa's floor as a log-RMSE (natural log,
geometric-mean-free: 0.2 = a factor of about 1.22 either way).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: default number of simulated noise draws (the floor's own sampling error is about 1 / sqrt(2 n) of it: 14 %)
N_DRAWS = 24
#: smallest shrinkage factor s (log kappa = s log kappa_hat) undone to recover kappa before the shrinkage
MIN_SHRINK = 0.05
#: the truth's spread of log kappa is taken as at least this share of the unshrunk estimate's
MIN_SPREAD_SHARE = 0.1


@dataclass(frozen=True)
class KappaFloor:
    """The accuracy floor of kappa on one recording (module docstring).

    node_error_px: e, the node error across the branch the floor assumes (px); source: where it came from.
    segment_px: (E,) the shorter of each bend's two segments in the rest pose (px).
    angle_noise_deg: (E,) the bend-angle noise e px gives after smoothing, e sqrt(gain (A A')_jj) (deg).
    bend_rms_deg: (E,) RMS of the fitted bending kappa_e z_t over the observed frames (deg): what has to be measured.
    log_rmse_per_segment: (E,) each segment's floor: the RMS over draws of its log kappa's error (geometric-mean-free;
        the shrinkage's pull as well as the scatter).
    log_rmse: kappa's log-RMSE (geometric-mean-free, RMS over draws) that the error alone gives.
    log_rmse_half_error: the same with half the node error (e / 2 px): what a better tracker or a 2x zoom buys.
    n_draws, seed: the simulation's size and seed. edges: (joint, child) of each row (empty where not given).
    """

    node_error_px: float
    source: str
    segment_px: np.ndarray
    angle_noise_deg: np.ndarray
    bend_rms_deg: np.ndarray
    log_rmse_per_segment: np.ndarray
    log_rmse: float
    log_rmse_half_error: float
    n_draws: int
    seed: int
    edges: tuple = ()

    def as_dict(self) -> dict:
        def fl(x):
            return [None if not np.isfinite(v) else float(v) for v in np.asarray(x, float)]
        return {"node_error_px": float(self.node_error_px), "node_error_source": self.source,
                "segment_px": fl(self.segment_px), "angle_noise_deg": fl(self.angle_noise_deg),
                "bend_rms_deg": fl(self.bend_rms_deg), "log_rmse_per_segment": fl(self.log_rmse_per_segment),
                "log_rmse": float(self.log_rmse), "log_rmse_half_error": float(self.log_rmse_half_error),
                "n_draws": int(self.n_draws), "seed": int(self.seed),
                "edges": [f"{j}->{c}" for j, c in self.edges],
                "meaning": "the kappa log-RMSE (geometric-mean-free) that white node errors of node_error_px "
                           "across the branch alone allow on this branch and this bending (simulated through the "
                           "same fit); an error that follows the motion costs more"}

    @classmethod
    def from_dict(cls, d: dict) -> "KappaFloor":
        """The floor back from its report.json form (:meth:`as_dict`)."""
        def arr(key):
            return np.array([np.nan if v is None else v for v in d.get(key) or []], float)
        edges = tuple(tuple(int(x) for x in e.split("->")) for e in d.get("edges") or [])
        return cls(node_error_px=float(d["node_error_px"]), source=str(d.get("node_error_source", "")),
                   segment_px=arr("segment_px"), angle_noise_deg=arr("angle_noise_deg"),
                   bend_rms_deg=arr("bend_rms_deg"), log_rmse_per_segment=arr("log_rmse_per_segment"),
                   log_rmse=float(d["log_rmse"]), log_rmse_half_error=float(d["log_rmse_half_error"]),
                   n_draws=int(d.get("n_draws", 0)), seed=int(d.get("seed", 0)), edges=edges)

    def line(self) -> str:
        """Two lines for the terminal summary: e, L, angle noise against bending, and the floor they set."""
        ok = np.isfinite(self.angle_noise_deg) & np.isfinite(self.bend_rms_deg)
        if not ok.any() or not np.isfinite(self.log_rmse):
            return ""
        an, br, L = self.angle_noise_deg[ok], self.bend_rms_deg[ok], self.segment_px[ok]
        buried = int(np.sum(an > br))
        text = (f"what limits kappa: a tracker error of {self.node_error_px:.2f} px across the branch ({self.source}, "
                f"before smoothing) on segments of {np.nanmin(L):.0f}-{np.nanmax(L):.0f} px (median "
                f"{np.nanmedian(L):.0f}) gives {np.median(an):.2f} deg of angle noise per bend against "
                f"{np.median(br):.2f} deg RMS of bending (medians)"
                + (f"; on {buried} of {ok.sum()} segments the noise exceeds the bending" if buried else "")
                + f".\n  That error alone, were it white, allows kappa to about x{np.exp(self.log_rmse):.2f} "
                f"(log-RMSE {self.log_rmse:.2f}{self._spread_text()}); x{np.exp(self.log_rmse_half_error):.2f} with "
                f"half of it (a 2x zoom, less compression or a better tracker). Intervals much wider than that: an "
                f"error that follows the motion, or a model that misses something")
        if buried > ok.sum() / 2:
            text += ("; with the noise above the bending on most segments the recording cannot show how uneven the "
                     "branch is, and the floor is only a rough guide")
        return text + " (docs/results.md, 'What limits κ')"


    def _spread_text(self) -> str:
        """"; median segment x.., worst j->c x.." where the segments' floors differ (one segment seen in a few
        frames can carry most of the log-RMSE)."""
        seg = self.log_rmse_per_segment
        ok = np.isfinite(seg)
        if ok.sum() < 2:
            return ""
        worst = int(np.nanargmax(seg))
        label = (f" {self.edges[worst][0]}->{self.edges[worst][1]}" if len(self.edges) == len(seg) else "")
        return f"; median segment x{np.exp(np.nanmedian(seg)):.2f}, worst{label} x{np.exp(seg[worst]):.2f}"


def _draws(pred, observed, weights, A, config, e, n_draws, rng, response):
    """(log |kappa|, log |kappa| before the shrinkage), each (n_draws, E), of refits of ``pred`` + A n with n white
    N(0, e^2) per node and frame, filtered by the smoother's gain ``response`` (T // 2 + 1,: |H| at the rfft
    frequencies; None = not smoothed)."""
    from .model.compliance import fit_batch
    E, T = pred.shape
    n = rng.standard_normal((n_draws, A.shape[1], T)) * e
    if response is not None:
        n = np.fft.irfft(np.fft.rfft(n, axis=-1) * response, n=T, axis=-1)
    Yb = pred[None] + np.einsum("en,bnt->bet", A, n)
    if config.response == "abs":
        Yb = np.abs(Yb)
    Yb[:, ~observed] = np.nan
    Wb = None if weights is None else np.broadcast_to(weights, Yb.shape)
    k, _, _, _, _, _, sh = fit_batch(Yb, config, Wb, None)
    logk = np.log(np.where(np.abs(k) > 0, np.abs(k), np.nan))
    return logk, logk / np.maximum(sh, MIN_SHRINK)


def _centred(x: np.ndarray) -> np.ndarray:
    return x - np.nanmean(x, axis=-1, keepdims=True)


def kappa_floor(z: np.ndarray, direction: np.ndarray, kappa_raw: np.ndarray, observed: np.ndarray,
                weights: np.ndarray | None, bends, rest_xy: dict, config, node_error_px: float,
                source: str = "given", n_draws: int = N_DRAWS, seed: int = 0, smoother=None,
                edges=()) -> KappaFloor | None:
    """The floor (module docstring) of a rank-1 fit with excitation ``z`` (T,, deg), signs ``direction`` (E,) and
    gains ``kappa_raw`` (E,, > 0) before the shrinkage, on the ``observed`` (E, T) entries, with the fit's
    ``weights`` (E, T or None) and ``config`` (:class:`~rce_gtsam.presets.ComplianceConfig`); ``bends``:
    (grandparent, joint, child) node ids per row; ``rest_xy``: {node id: (2,) px}; ``smoother``: (presmooth window,
    w_m, w_v, w_a) of the smoother the tracks went through
    (:func:`~rce_gtsam.diagnosis.noise_floor.smoother_weights`; None: the node errors reach the bends unsmoothed).
    None where the geometry or e is unusable. ``edges``: (joint, child) per row, for the report.

    The simulated branch's kappa is the recording's, spread as the truth's is estimated to be: the shrunk kappa
    is too even (it is a posterior mean) and the unshrunk one too uneven (its noise adds to the spread), and either
    would misstate what the shrinkage costs. So a first set of draws from the unshrunk kappa measures each
    segment's noise variance v_e of log kappa before shrinkage; the truth's spread is taken as
    var(log kappa_raw) - mean(v_e) (at least :data:`MIN_SPREAD_SHARE` of it), and log kappa_raw is scaled to it.
    """
    from .diagnosis.noise_floor import smoother_response
    from .diagnosis.noise_floor_nodewise import angle_sensitivity

    e = float(node_error_px)
    A = angle_sensitivity(list(bends), rest_xy)
    kraw = np.asarray(kappa_raw, float)
    good = np.isfinite(kraw) & (kraw > 0)
    if not (np.isfinite(e) and e > 0) or not np.isfinite(A).all() or good.sum() < 2:
        return None
    config = replace(config, correlated=False) if getattr(config, "correlated", False) else config
    T = len(z)
    H = None if smoother is None else smoother_response(np.fft.rfftfreq(T), *smoother)
    zz = np.where(np.isfinite(z), np.asarray(z, float), 0.0)
    sign = np.asarray(direction, float)

    def predict(logk):
        return np.where(observed, (np.exp(logk) * sign)[:, None] * zz[None, :], 0.0)

    lraw = _centred(np.where(good, np.log(np.where(good, kraw, 1.0)), np.nan))
    lraw = np.where(good, lraw, 0.0)
    _, raw_draws = _draws(predict(lraw), observed, weights, A, config, e, n_draws, np.random.default_rng(seed), H)
    v = np.nanvar(_centred(raw_draws), axis=0)
    spread = float(np.var(lraw[good]))
    truth_spread = max(spread - float(np.nanmean(v[good])), MIN_SPREAD_SHARE * spread)
    lref = lraw * np.sqrt(truth_spread / spread) if spread > 0 else lraw

    def floor_at(err, rng):
        logk, _ = _draws(predict(lref), observed, weights, A, config, err, n_draws, rng, H)
        d = _centred(np.where(good, logk - lref[None], np.nan))
        per_draw = np.sqrt(np.nanmean(d ** 2, axis=1))
        return float(np.sqrt(np.mean(per_draw ** 2))), np.sqrt(np.nanmean(d ** 2, axis=0))

    log_rmse, per_segment = floor_at(e, np.random.default_rng(seed + 1))
    half, _ = floor_at(e / 2, np.random.default_rng(seed + 2))
    gain = 1.0 if H is None else float(np.mean(H ** 2))
    seg = np.array([min(np.linalg.norm(np.subtract(rest_xy[m], rest_xy[g])),
                        np.linalg.norm(np.subtract(rest_xy[c], rest_xy[m]))) for g, m, c in bends])
    n_obs = np.maximum(observed.sum(axis=1), 1)
    bend_rms = np.sqrt((predict(lref) ** 2).sum(axis=1) / n_obs)
    return KappaFloor(node_error_px=e, source=source, segment_px=seg,
                      angle_noise_deg=e * np.sqrt(gain * np.diag(A @ A.T)), bend_rms_deg=bend_rms,
                      log_rmse_per_segment=np.where(good, per_segment, np.nan), log_rmse=log_rmse,
                      log_rmse_half_error=half, n_draws=int(n_draws), seed=int(seed), edges=tuple(tuple(e) for e in edges))


def kappa_floor_of(result, node_error_px: float | None = None, n_draws: int = N_DRAWS,
                   seed: int = 0) -> KappaFloor | None:
    """:func:`kappa_floor` of an :class:`~rce_gtsam.pipeline.AnalysisResult`'s rank-1 fit. ``node_error_px``: None
    takes the node-wise noise floor's estimate from the fit's residuals (source "estimated from the residuals"), or,
    where too few bends share a node for it, the tracker's median sigma_px (source "the tracker's own sigma"); None
    where neither exists."""
    from .diagnosis.noise_floor import nodewise_of, rest_positions, smoother_response, smoother_weights

    fit = getattr(result, "fit", None)
    if fit is None or getattr(fit, "z", None) is None or getattr(fit, "shrinkage", None) is None:
        return None
    r = result.response
    bends = result.bending.nodes_of(r.bend_rows)
    source = "given"
    smoother = smoother_weights(result)
    if node_error_px is None:
        # the node-wise estimate reads the error after smoothing: the raw error is larger by 1 / sqrt(gain)
        nw = nodewise_of(result, bends)
        gain = float(np.mean(smoother_response(np.fft.rfftfreq(r.Y.shape[1]), *smoother) ** 2))
        node_error_px = float("nan") if nw is None else nw.sigma_px / np.sqrt(gain)
        source = "estimated from the residuals"
        sig = result.tracks.sigma_px
        if not np.isfinite(node_error_px) and sig is not None and np.isfinite(sig).any():
            # too few bends sharing a node to read it from the residuals (MIN_PAIRS): the tracker's own word
            node_error_px, source = float(np.nanmedian(sig)), "the tracker's own sigma"
    rest_xy = rest_positions(result, bends)
    weights = r.weights if result.preset.compliance.weighted else None
    kappa = np.asarray(fit.kappa, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa_raw = np.exp(np.log(kappa) / np.maximum(np.asarray(fit.shrinkage, float), MIN_SHRINK))
    return kappa_floor(fit.z, fit.direction, kappa_raw, np.isfinite(r.Y), weights, bends, rest_xy,
                       result.preset.compliance, node_error_px, source, n_draws=n_draws, seed=seed,
                       smoother=smoother, edges=r.edges)
