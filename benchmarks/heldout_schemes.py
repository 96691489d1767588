"""Alternative held-out schemes for the second excitation (``second_mode``), measured beside the diagnosis' own
(:mod:`rce_gtsam.diagnosis.heldout`) by ``benchmarks/beam_ideal_oracle.py``. An experiment, not the diagnosis.

The diagnosis' scheme (every candidate alike): per contiguous fold block, the model is refitted on the frames
outside the block and its buffers (all rows); on the block, z and w are re-estimated from one node-disjoint row
set A (every static parameter frozen) and the other set B is scored, then the roles swap. On a chain of 18 bends
:func:`rce_gtsam.model.row_sets.node_disjoint_split` deals A A A, gap, gap, B B B, gap, gap: about 5 rows per
set, 8 rows neither estimate nor are scored. The held-out z and w come from ``ResponseModel.solve(frozen=True)``:
alternating a W-weighted least-squares z step (ridge prior) and the second mode's GLS w step (N(0, 1) prior,
the noise variance frozen from training), ``CV_ITER`` sweeps.

Measured here, per fold, on the same training refits (:func:`fold_refits`):

* ``halves_code``: the diagnosis' own prediction (the candidate's fold t);
* ``halves_gls``: same rows, z and w as one joint GLS posterior mean per frame (:func:`joint_posterior`: the
  rows' noise correlation C from the training residual's frame differences, N(0, var z) and N(0, 1) priors,
  the training residual variance as noise variance);
* ``halves_signature``: the diagnosis' rank-1 held-out prediction plus the true signature on B (knows the
  extra signal exactly): the ceiling of the diagnosis' held-out fold t on these rows and folds;
* ``bcv_gls``: bi-cross-validation (Owen & Perry 2009) with the node rule: the rows are cut into runs of 3
  along the branch (:func:`rce_gtsam.model.row_sets.walk_order`); each run B is scored from the latents
  estimated on every row that shares no tracked node with B (about 11 of 18), so every row is scored and the
  estimate uses twice the rows, while no node's noise reaches both sides;
* ``bcv_signature``: the same ceiling on the bi-cross-validation rows.

Each scheme's rank-1 baseline is scored on the same rows and frames (its z: the W-weighted ridge estimate of
the diagnosis for ``halves_code`` and ``halves_signature``, the rank-1 GLS posterior for the ``*_gls`` schemes and
``bcv_signature``: a GLS z alone predicts better than the W-weighted one where neighbouring rows' noise is
correlated, which is no second mode — against the W-weighted baseline, ``halves_gls`` gave t 4.2 on an
effect-free own-simulator recording) and the fold t is
:func:`rce_gtsam.diagnosis.heldout.paired_t` of the per-fold log MSE ratios. Units: degrees, deg^2, frames.
"""

from __future__ import annotations

import numpy as np

from rce_gtsam.diagnosis.heldout import blank_latents, paired_t
from rce_gtsam.diagnosis.settings import CV_ITER
from rce_gtsam.diagnosis.statistics import noise_correlation
from rce_gtsam.model.row_sets import shared_node_matrix, walk_order

SCHEMES = ("halves_code", "halves_gls", "halves_signature", "bcv_gls", "bcv_signature")


def bcv_sets(s: np.ndarray, edge_nodes=None, run: int = 3) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(A, B)]: B runs of ``run`` rows along the branch, A every row sharing no tracked node with B (>= 2 rows)."""
    shared = shared_node_matrix(s, edge_nodes)
    order = walk_order(s, shared, edge_nodes)
    out = []
    for i in range(0, len(order), run):
        B = np.sort(order[i:i + run])
        A = np.flatnonzero(~shared[B].any(axis=0))
        if len(A) >= 2:
            out.append((A, B))
    return out


def joint_posterior(K: np.ndarray, corr: np.ndarray, y: np.ndarray, prior_prec: np.ndarray) -> np.ndarray:
    """(L, T) posterior mean of L latents per frame from rows y (n, T; NaN = missing) = K (n, L) theta_t + noise,
    noise correlation ``corr`` (n, n) times the noise variance; ``prior_prec`` (L,): prior precisions in units of
    the noise variance (noise variance / latent variance)."""
    ok = np.isfinite(y)
    out = np.zeros((K.shape[1], y.shape[1]))
    patterns, which = np.unique(ok.T, axis=0, return_inverse=True)
    for p_i, o in enumerate(patterns):
        cols = np.flatnonzero(np.ravel(which) == p_i)
        if not o.any():
            continue
        P = np.linalg.inv(corr[np.ix_(o, o)])
        Ko = K[o]
        M = Ko.T @ P @ Ko + np.diag(prior_prec)
        out[:, cols] = np.linalg.solve(M, Ko.T @ P @ y[np.ix_(o, cols)])
    return out


def fold_refits(base_model, base, model, full, Y, W, s, blocks, gap: int):
    """Per fold block: (a, b, lo, hi, rank-1 training fit, second-mode training fit) as the diagnosis refits them."""
    T = Y.shape[1]
    for a, b in blocks:
        lo, hi = max(0, a - gap), min(T, b + gap)
        Ytr, Wtr = Y.copy(), W.copy()
        Ytr[:, lo:hi], Wtr[:, lo:hi] = np.nan, 0.0
        if not (Wtr > 0).any(axis=1).all():
            continue
        z0 = full.z.copy()
        z0[lo:hi] = 0.0
        st0 = {e.name: blank_latents(x, lo, hi) for e, x in zip(full.model.effects, full.states)}
        tr = model.solve(Ytr, Wtr, s, start=(full.kappa.copy(), z0, st0), max_iter=CV_ITER, refit_shared=False,
                         z_ridge=full.heldout_z_precision())
        zb = base.z.copy()
        zb[lo:hi] = 0.0
        trb = base_model.solve(Ytr, Wtr, s, start=(base.kappa.copy(), zb, {}), max_iter=CV_ITER, refit_shared=False,
                               z_ridge=base.heldout_z_precision())
        yield a, b, lo, hi, trb, tr


def scheme_fold_t(base_model, base, model, full, Y, W, s, blocks, gap: int, halves, edge_nodes=None,
                  signature: np.ndarray | None = None) -> dict:
    """{scheme: {"t": fold t against its own rank-1 baseline, "gain_pct": held-out RMSE reduction (%)}} for the
    module's schemes (``*_signature`` only with the true ``signature``, E x T deg)."""
    E, T = Y.shape
    bcv = bcv_sets(s, edge_nodes)
    sse = {k: np.zeros((len(blocks), 4)) for k in SCHEMES}  # candidate sse, n, baseline sse, n
    for k, (a, b, lo, hi, trb, tr) in enumerate(fold_refits(base_model, base, model, full, Y, W, s, blocks, gap)):
        cols = np.arange(a, b)
        trained = np.ones(T, bool)
        trained[lo:hi] = False
        sm = tr.states[-1]
        mu = sm["params"]["mu"]
        res_b = np.where(W > 0, Y - trb.predict(), np.nan)[:, trained]
        res_c = np.where(W > 0, Y - tr.predict(), np.nan)[:, trained]
        corr_b, corr_c = noise_correlation(res_b), noise_correlation(res_c)
        var_b, var_c = float(np.nanmean(res_b ** 2)), float(np.nanmean(res_c ** 2))
        zv_b, zv_c = float(np.mean(trb.z[trained] ** 2)), float(np.mean(tr.z[trained] ** 2))
        lam_ols = trb.heldout_z_precision(trained)
        free = np.zeros(T, bool)
        free[lo:hi] = True
        window = np.arange(lo, hi)
        st = {e.name: x for e, x in zip(model.effects, tr.states)}
        for A, B in (tuple(halves), tuple(halves)[::-1]):
            yA, yB = Y[np.ix_(A, cols)], Y[np.ix_(B, cols)]
            Wa = W[np.ix_(A, cols)]
            zb = ((Wa * trb.kappa[A, None] * np.nan_to_num(yA)).sum(0)
                  / ((Wa * trb.kappa[A, None] ** 2).sum(0) + lam_ols))
            base_pred = trb.kappa[B, None] * zb[None]
            Yte = np.full_like(Y, np.nan)
            Yte[np.ix_(A, window)] = Y[np.ix_(A, window)]
            est = model.solve(Yte, np.where(np.isfinite(Yte), W, 0.0), s, start=(tr.kappa.copy(), tr.z.copy(), st),
                              frozen=True, free=free, max_iter=CV_ITER, z_ridge=tr.heldout_z_precision(trained))
            _add(sse["halves_code"], k, yB, est.predict()[np.ix_(B, cols)], base_pred)
            th = joint_posterior(np.stack([tr.kappa[A], mu[A]], 1), corr_c[np.ix_(A, A)], yA,
                                 np.array([var_c / zv_c, var_c]))
            zg = joint_posterior(trb.kappa[A, None], corr_b[np.ix_(A, A)], yA, np.array([var_b / zv_b]))[0]
            _add(sse["halves_gls"], k, yB, tr.kappa[B, None] * th[0] + mu[B, None] * th[1],
                 trb.kappa[B, None] * zg[None])
            if signature is not None:
                _add(sse["halves_signature"], k, yB, base_pred + signature[np.ix_(B, cols)], base_pred)
        for A, B in bcv:
            yA, yB = Y[np.ix_(A, cols)], Y[np.ix_(B, cols)]
            zb = joint_posterior(trb.kappa[A, None], corr_b[np.ix_(A, A)], yA, np.array([var_b / zv_b]))[0]
            base_pred = trb.kappa[B, None] * zb[None]
            th = joint_posterior(np.stack([tr.kappa[A], mu[A]], 1), corr_c[np.ix_(A, A)], yA,
                                 np.array([var_c / zv_c, var_c]))
            _add(sse["bcv_gls"], k, yB, tr.kappa[B, None] * th[0] + mu[B, None] * th[1], base_pred)
            if signature is not None:
                _add(sse["bcv_signature"], k, yB, base_pred + signature[np.ix_(B, cols)], base_pred)
    out = {}
    for name, v in sse.items():
        used = (v[:, 1] > 0) & (v[:, 3] > 0)
        if not used.any():
            continue
        mse_c, mse_b = v[used, 0] / v[used, 1], v[used, 2] / v[used, 3]
        gain = 100.0 * (1 - np.sqrt(v[used, 0].sum() / v[used, 1].sum() / (v[used, 2].sum() / v[used, 3].sum())))
        out[name] = {"t": float(paired_t(mse_b, mse_c)), "gain_pct": float(gain)}
    return out


def _add(acc: np.ndarray, k: int, y: np.ndarray, pred: np.ndarray, base_pred: np.ndarray) -> None:
    """Add fold ``k``'s squared errors of ``pred`` and ``base_pred`` on ``y`` (NaN = missing) to ``acc``."""
    ok = np.isfinite(y)
    acc[k, 0] += float(np.sum(np.where(ok, (y - pred) ** 2, 0.0)))
    acc[k, 1] += int(ok.sum())
    acc[k, 2] += float(np.sum(np.where(ok, (y - base_pred) ** 2, 0.0)))
    acc[k, 3] += int(ok.sum())
