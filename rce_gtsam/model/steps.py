"""The public solver steps of the response model, which effects call while they fit.

One block-coordinate sweep of :meth:`rce_gtsam.model.ResponseModel.solve` is :func:`kappa_step`,
:func:`z_step`, then each effect's ``update``. Effects use :func:`sse_after_z` (error of a candidate state
after an exact z step: grid starts) and :func:`profiled_sse` (the same with the effect's slot replaced:
profiling z out of a shared parameter), and :meth:`~rce_gtsam.model.view.FitView.index_of` to find their
own slot. The kappa step is the rank-1 solver's (:mod:`rce_gtsam.model.compliance`): the same shrinkage of
log kappa (``count`` or ``precision``, from the model's :class:`~rce_gtsam.presets.ComplianceConfig`) and the
same geometric-mean normalisation, applied to a Gauss-Newton step through the effects. Units: degrees,
frames.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.linalg import LinearOperator, cg

from .compliance import EPS, log_normal_shrinkage, shrink_and_normalise
from .view import FitView


def kappa_step(view: FitView) -> None:
    """Gauss-Newton kappa step (exact least squares when g is linear), shrinkage, normalisation.

    With no effects this is the rank-1 solver's kappa step (:func:`rce_gtsam.model.compliance.fit_rank1_batch`):
    kappa_hat_e = sum_t w z y / sum_t w z^2 over frames with |z| > EPS, then shrinkage by the model's
    config (``count``: s = n / (n + lambda); ``precision``: the log-normal prior with the residual variance
    and lag-1 autocorrelation of the edge's regression, :func:`precision_shrinkage`) and geometric-mean
    normalisation; z is multiplied by the geometric mean divided out, so kappa * z is unchanged by it."""
    cfg = view.model.config
    pred, X, dG = view.parts()
    r = view.Y0 - pred
    J = dG * X
    for eff, st in zip(view.effects, view.states):
        if eff.kind == "output":
            J = J + eff.output_kappa_term(dG, st, view.kappa)
    used = (view.W > 0) & (np.abs(X) > EPS)
    Wm = np.where(used, view.W, 0.0)
    num = np.sum(Wm * J * r, axis=1)
    den = np.sum(Wm * J * J, axis=1)
    counts = used.astype(float) if view.frame_counts is None else used * view.frame_counts[None, :]
    n = counts.sum(axis=1)
    k_hat = view.kappa + num / np.maximum(den, EPS)
    signed = cfg.response == "signed"
    if not signed:
        k_hat = np.maximum(k_hat, EPS)
    if cfg.shrinkage == "precision":
        r_hat = np.where(used, r - (k_hat - view.kappa)[:, None] * J, 0.0)
        shrink = precision_shrinkage(r_hat, used, Wm, den, n, k_hat, float(cfg.prior_sd_log))
    else:
        shrink = n / (n + float(cfg.prior_strength))
    k_new, _, gm = shrink_and_normalise(k_hat[None], shrink[None], n[None], signed)
    view.kappa = k_new[0]
    view.z = view.z * gm[0]  # keeps kappa * z (and any operator of z) unchanged
    if gm[0] != 1.0 and view.states:  # and every parameter that is in units of z (Effect.rescale_z)
        view.states = [eff.rescale_z(st, float(gm[0])) for eff, st in zip(view.effects, view.states)]
    view.shrinkage = np.where(n > 0, shrink, 1.0)


def precision_shrinkage(r_hat, used, Wm, den, n, k_hat, tau: float) -> np.ndarray:
    """(E,) tau^2 / (tau^2 + se^2(log kappa_hat)) from the residuals ``r_hat`` (E, T) of each edge's
    regression at kappa_hat: the weighted residual variance over the ``used`` entries (weights ``Wm``,
    n of them) divided by the information ``den``, inflated by the lag-1 autocorrelation of the residuals
    (:func:`rce_gtsam.model.compliance.log_normal_shrinkage`; the same estimate the rank-1 solver makes)."""
    sigma2 = np.sum(Wm * r_hat * r_hat, axis=1) / np.maximum(n - 1, 1)
    rho = lag1_autocorrelation(r_hat, used)
    return log_normal_shrinkage(sigma2 / np.maximum(den, EPS), rho, k_hat, tau)


def lag1_autocorrelation(r: np.ndarray, used: np.ndarray) -> np.ndarray:
    """(E,) each row's lag-1 autocorrelation of the residuals ``r`` (E, T) over pairs of ``used`` frames (r
    taken as 0 elsewhere), clipped to [0, 0.99]: the rho of the AR(1) variance inflation (1 + rho) / (1 - rho)."""
    r = np.where(used, r, 0.0)
    both = used[:, 1:] & used[:, :-1]
    lag = np.sum(np.where(both, r[:, 1:] * r[:, :-1], 0.0), axis=1)
    return np.clip(lag / np.maximum(np.sum(r * r, axis=1), 1e-300), 0.0, 0.99)


def z_step(view: FitView) -> None:
    """Gauss-Newton z step on the free frames (exact when the model is linear in z)."""
    pred, X, dG = view.parts()
    r = view.Y0 - pred
    C = dG * view.kappa[:, None]
    WC = view.W * C
    has_op = any(e.kind == "operator" for e in view.effects)
    free = view.free
    lam = view.z_ridge
    if not has_op:
        den = np.sum(WC * C, axis=0) + lam
        ok = free & (den > EPS)
        dz = np.where(ok, (np.sum(WC * r, axis=0) - lam * view.z) / np.where(ok, den, 1.0), 0.0)
    else:
        dz = operator_z_solve(view, C, r, free)
    new_z = view.z + dz
    if view.model.config.response == "abs":
        new_z = np.maximum(new_z, 0.0)
    if any(e.kind == "output" for e in view.effects):
        # Gauss-Newton on a nonlinear g: halve the step until the error does not grow
        old = view.wsse()
        step = 1.0
        for _ in range(6):
            if view.wsse(z=view.z + step * (new_z - view.z)) <= old:
                break
            step *= 0.5
        new_z = view.z + step * (new_z - view.z)
    view.z = new_z


def core_step(view: FitView) -> None:
    """One kappa step and one z step."""
    kappa_step(view)
    z_step(view)


def sse_after_z(view: FitView, index: int, state: dict) -> float:
    """Weighted SSE (deg^2) of the model's first ``index`` + 1 effects, effect ``index`` in ``state``, after
    one exact z step with kappa and the other effects fixed. For an effect's ``init`` (its grid start):
    ``view`` holds the ``index`` effects initialised so far."""
    model = getattr(view, "full_model", view.model)
    sub = model.with_effects(model.effects[: index + 1])
    v = view.copy_with(sub, list(view.states)[:index] + [state])
    z_step(v)
    return v.wsse()


def profiled_sse(view: FitView, index: int, state: dict) -> float:
    """Weighted SSE (deg^2) with effect ``index`` in ``state`` after an exact z step (kappa and the other
    effects fixed): the error profiled over z, for an effect's ``update`` of a parameter coupled to z."""
    v = view.copy_with(view.model, view.with_state(index, state))
    z_step(v)
    return v.wsse()


# Relative Tikhonov ridge of the iterative z solve (fraction of a typical frame's information). Operators
# with memory (dynamics) attenuate high frequencies of z, whose components are then barely determined by
# the data; 1e-3 keeps them bounded while biasing well-determined components by ~0.1 %.
Z_RIDGE = 1e-3


def _unseen_to_prior_mean(view: FitView, dz: np.ndarray, unseen: np.ndarray) -> None:
    """dz that moves the ``unseen`` frames' z to the prior mean 0 when the z prior is on (in place)."""
    if view.z_ridge > 0:
        dz[unseen] = -view.z[unseen]


def operator_z_solve(view: FitView, C: np.ndarray, r: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Gauss-Newton step dz of  min sum_e,t W (r - C L_e dz)^2  over the free frames, operators present.

    Frames whose z no observation touches (through the operators: past a lag's reach at the recording's end)
    are not solved for: nothing in the data determines them. With the z prior on (``view.z_ridge`` > 0) they
    are set to its mean, 0 (their posterior mean); left alone they would only be rescaled by every kappa step's
    normalisation, which compounded to z = -146 deg on a 4-row delay fit whose data lie within +-3 deg.
    Direct path: a single operator that exposes ``sparse_operator`` (delay) gives a sparse, banded normal
    matrix, solved exactly with a sparse LU. Otherwise preconditioned conjugate gradients, with the
    circulant approximation of the normal matrix (sum_e mean(D_e) |H_e(f)|^2, from the operators'
    ``transfer``) as the preconditioner when every operator provides its frequency response — it is
    exact for full, evenly weighted data, so CG needs few iterations; Jacobi otherwise.
    """
    from scipy import sparse
    from scipy.sparse.linalg import spsolve

    T = view.T
    D = view.W * C * C
    ops = [(e, st) for e, st in zip(view.effects, view.states) if e.kind == "operator"]
    dz = np.zeros(T)
    lam = view.z_ridge
    rhs = view.transform_T(view.W * C * r) - lam * view.z
    if len(ops) == 1 and hasattr(ops[0][0], "sparse_operator"):
        L = ops[0][0].sparse_operator(ops[0][1], view)
        A = (L.T @ sparse.diags(D.ravel()) @ L).tocsc()
        diag = A.diagonal()
        med = max(float(np.median(diag[diag > 0])) if (diag > 0).any() else 1.0, EPS)
        seen = diag > 1e-9 * med
        idx = np.flatnonzero(free & seen)
        _unseen_to_prior_mean(view, dz, free & ~seen)
        if idx.size == 0:
            return dz
        Aff = A[idx][:, idx] + sparse.identity(idx.size, format="csc") * (1e-9 * med + lam)
        dz[idx] = spsolve(Aff.tocsc(), rhs[idx])
        return dz
    support = np.abs(view.transform_T(D))
    med = max(float(np.median(support[support > 0])) if (support > 0).any() else 1.0, EPS)
    seen = support > 1e-9 * med
    idx = np.flatnonzero(free & seen)
    _unseen_to_prior_mean(view, dz, free & ~seen)
    if idx.size == 0:
        return dz
    ridge = Z_RIDGE * med + lam
    transfers = [e.transfer(st, view, 2 * T) if hasattr(e, "transfer") else None for e, st in ops]
    if all(h is not None for h in transfers):
        H2 = np.ones((view.E, T + 1))
        for h in transfers:
            H2 = H2 * np.abs(h) ** 2
        P = np.sum(D[:, idx].mean(axis=1)[:, None] * H2, axis=0) + ridge  # data density where z is free

        def precond(v):
            full = np.zeros(T)
            full[idx] = v
            return np.fft.irfft(np.fft.rfft(full, 2 * T) / P, 2 * T)[:T][idx]
    else:
        dj = support[idx] + ridge

        def precond(v):
            return v / dj

    def matvec(v):
        full = np.zeros(T)
        full[idx] = v
        return (view.transform_T(D * view.transform(full)) + ridge * full)[idx]

    n = idx.size
    A = LinearOperator((n, n), matvec=matvec, dtype=float)
    M = LinearOperator((n, n), matvec=precond, dtype=float)
    sol, _ = cg(A, rhs[idx], rtol=1e-3, maxiter=25, M=M)
    dz[idx] = sol
    return dz
