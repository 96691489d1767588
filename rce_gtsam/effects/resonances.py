"""``resonances``: inertia with each joint's own natural frequency (another form of ``dynamics``).

Physics: the same damped second-order response as :mod:`.dynamics`,
y'' + 2 zeta omega_e y' + omega_e^2 y = omega_e^2 kappa_e z (time in frames, omega in rad/frame, static gain 1),
but omega_e is free for every joint instead of log-linear in root distance. A real branch's natural frequencies
follow its masses (leaves, fruit, side shoots) and stiffnesses joint by joint, not its length: a leafy mid-branch
joint can resonate lower than the tip. zeta is shared.

Why a second form: on simulated joints whose periods are scattered along the branch (each log-uniform in
[T_tip/3, T_tip], ``rce simulate --form scattered``) the graded form cannot follow them. At 2x the default
strength (10 recordings, default preset, ``bench_diagnose.py --held-out``) its fit *raised* the held-out RMSE on
7 of 10 (by up to 6 %), while this form lowered it on 8 of 10 (by up to 42 %): the verdict named dynamics on 4
(3 before), at 1x on 3 (1 before; the oracle 8 and 6). That simulator form was the project's held-out check of
the diagnosis; it is not held out for this candidate any more.

A verdict for this effect reports the finding ``dynamics`` (:attr:`~rce_gtsam.effects.Effect.finding`) and
records this form. With E + 1 parameters it has no fixed low-dimensional signature for a full-data score test
(:meth:`score_directions` is None): the held-out test alone judges it. Where it is not significantly better than
a supported graded form, the graded form leads the verdict
(:func:`~rce_gtsam.diagnosis.verdict.leading_candidate`), and the parsimony rule prefers a delay (1 parameter)
unless a form of inertia is significantly better.

Units: frames, rad/frame, degrees.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from ..diagnosis.statistics import per_edge_regression
from .base import Parameter, scalar
from .dynamics import OMEGA_MAX, OMEGA_MIN, ZETA_MAX, ZETA_MIN, ZETA_STARTS, Dynamics

DIFF_STEP = 1e-4  # finite-difference step in log w (rad/frame) and zeta
#: the per-joint grid start: natural periods (frames) from 2 to the longest the bounds allow, and damping ratios
INIT_PERIODS = np.geomspace(2.0, 2 * np.pi / OMEGA_MIN, 12)
INIT_ZETAS = (0.1, 0.3)
#: a joint whose natural frequency is within this factor of the upper bound is reported as quasi-static
QUASI_STATIC = 0.95
LM_DAMPING = 1e-3  # Marquardt damping of the first try, relative to the normal matrix's diagonal
LM_STEPS = 2  # steps per update (z fixed), each of up to LM_TRIES tries
LM_TRIES = 4  # tries per step, the damping x10 after each that does not lower the error


class Resonances(Dynamics):
    """Per-joint damped 2nd-order response: a free natural frequency for every joint, a shared damping ratio."""

    name = "resonances"
    finding = "dynamics"
    kind = "operator"
    equation = "y_e'' + 2 zeta w_e y_e' + w_e^2 y_e = w_e^2 kappa_e z   (w_e free per joint, rad/frame)"
    fitting = ("started from each joint's best period on a grid; (log w_e, zeta) by bounded Levenberg-Marquardt "
               "steps with kappa and z fixed (each joint's residual depends on its own w_e only), alternating with "
               "the core")
    physics = ("the segments have inertia and resonate, each at a natural frequency of its own that does not "
               "follow its place on the branch (leaves, fruit or side shoots loading some joints): they lag, "
               "amplify near resonance and ring after gusts. Kappa is then the static (low-frequency) gain; "
               "compare the fitted periods with where the branch carries mass.")
    score_excitation = "other_rows"

    def parameters(self, n_edges: int):
        return (Parameter("omega", "rad/frame", OMEGA_MIN, OMEGA_MAX, per_edge=True,
                          description="natural frequency of the joint"),
                Parameter("zeta", "1", ZETA_MIN, ZETA_MAX, description="damping ratio"))

    @staticmethod
    def omegas(state, s):
        return np.asarray(state["params"]["omega"], float) * np.ones(len(s))

    @staticmethod
    def _joint_state(log_omega, zeta):
        return {"params": {"omega": np.exp(np.asarray(log_omega, float)), "zeta": np.array(float(zeta))},
                "latents": {}}

    def init(self, view) -> dict:
        """Each joint's best natural period on a grid (:data:`INIT_PERIODS` frames, and quasi-static), for each
        damping ratio of :data:`INIT_ZETAS`, with kappa and z held at the current core fit; the damping ratio whose
        per-joint best fits lower in total is kept. Joint e's prediction depends on its own w_e only, so one
        prediction per grid value scores every joint at once (a start from the graded form's best grid point
        stayed quasi-static where the joints scatter: the Jacobian vanishes there)."""
        i = len(view.states)
        model = getattr(view, "full_model", view.model)
        sub = model.with_effects(model.effects[: i + 1])
        omegas = np.r_[OMEGA_MAX, 2 * np.pi / INIT_PERIODS]
        obs = view.W > 0
        best = None
        for zeta in INIT_ZETAS:
            sse = np.stack([np.sum(np.where(obs, view.W * (view.Y0 - view.copy_with(
                sub, list(view.states)[:i] + [self._joint_state(np.full(view.E, np.log(w)), zeta)]).predict()) ** 2,
                0.0), axis=1) for w in omegas])  # (grid, E)
            pick = np.argmin(sse, axis=0)
            total = float(sse[pick, np.arange(view.E)].sum())
            if best is None or total < best[0]:
                best = (total, np.log(omegas[pick]), zeta)
        return self._joint_state(best[1], best[2])

    def update(self, state, view, frozen):
        """:data:`LM_STEPS` Levenberg-Marquardt steps on (log w_e, zeta) with kappa and z fixed (a few steps per fit, as for the
        graded form: :meth:`Dynamics.update` says why not more). Joint e's residuals depend on w_e and zeta only,
        so the Jacobian takes two extra evaluations of the prediction, whatever the number of joints: all w_e
        moved at once, then zeta; the normal equations are an arrow matrix, solved densely (E + 1 unknowns)."""
        if frozen:
            return state
        i = view.index_of(self)
        E = len(view.s)
        lo = np.r_[np.full(E, np.log(OMEGA_MIN)), ZETA_MIN]
        hi = np.r_[np.full(E, np.log(OMEGA_MAX)), ZETA_MAX]
        p = state["params"]
        x = np.clip(np.r_[np.log(np.asarray(p["omega"], float)), scalar(p["zeta"])], lo, hi)
        obs = view.W > 0
        sw = np.sqrt(np.where(obs, view.W, 0.0))

        def residual(q):
            pred = view.predict(view.with_state(i, self._joint_state(q[:E], q[E])))
            return np.where(obs, (view.Y0 - pred) * sw, 0.0)

        for _ in range(LM_STEPS):
            x, moved = self._lm_step(x, residual, lo, hi, E)
            if not moved:
                break
        return self._joint_state(x[:E], x[E])

    @staticmethod
    def _lm_step(x, residual, lo, hi, E):
        """One damped Gauss-Newton step from x; (new x, whether it lowered the error)."""
        r0 = residual(x)
        f0 = float(np.sum(r0 * r0))
        # forward differences, backward where a parameter sits at its upper bound
        hw = np.where(x[:E] + DIFF_STEP <= hi[:E], DIFF_STEP, -DIFF_STEP)
        hz = DIFF_STEP if x[E] + DIFF_STEP <= hi[E] else -DIFF_STEP
        Jw = (residual(np.r_[x[:E] + hw, x[E]]) - r0) / hw[:, None]  # row e: d r_e / d log w_e
        Jz = (residual(np.r_[x[:E], x[E] + hz]) - r0) / hz            # d r / d zeta
        A = np.zeros((E + 1, E + 1))
        A[np.arange(E), np.arange(E)] = np.sum(Jw * Jw, axis=1)
        A[:E, E] = A[E, :E] = np.sum(Jw * Jz, axis=1)
        A[E, E] = np.sum(Jz * Jz)
        g = np.r_[np.sum(Jw * r0, axis=1), np.sum(Jz * r0)]
        scale = np.maximum(np.diag(A), 1e-300)
        lam = LM_DAMPING
        for _ in range(LM_TRIES):
            try:
                step = np.linalg.solve(A + lam * np.diag(scale), -g)
            except np.linalg.LinAlgError:
                break
            cand = np.clip(x + step, lo, hi)
            if np.sum(residual(cand) ** 2) < f0:
                return cand, True
            lam *= 10.0
        return x, False

    def alternative_starts(self, state):
        """The fitted frequencies with each damping ratio of :data:`~rce_gtsam.effects.dynamics.ZETA_STARTS` more
        than a factor 1.5 from the fitted one (see :meth:`Dynamics.alternative_starts`)."""
        p = state["params"]
        zeta = scalar(p["zeta"])
        logs = np.log(np.asarray(p["omega"], float))
        return [self._joint_state(logs, z) for z in ZETA_STARTS if abs(np.log(z / zeta)) > np.log(1.5)]

    def score_directions(self, kappa, z, s):
        return None  # E + 1 free parameters: no fixed signature; the held-out test judges this form

    def describe(self, state):
        """Natural periods (frames) of the joints that resonate, and how many joints are quasi-static (their
        frequency at the upper bound, a period of one frame: no inertia the data can see)."""
        om = np.asarray(state["params"]["omega"], float)
        static = om >= QUASI_STATIC * OMEGA_MAX
        periods = 2 * np.pi / om[~static] if (~static).any() else np.array([2 * np.pi / OMEGA_MAX])
        return {"period_shortest_frames": float(periods.min()), "period_median_frames": float(np.median(periods)),
                "period_longest_frames": float(periods.max()), "quasi_static_joints": float(static.sum())}

    def evidence(self, ctx) -> dict:
        """Do the joints differ in inertia beyond what one law along the branch explains? Each joint's residual
        is regressed on kappa_e d2z/dt2 (its own acceleration coefficient, frames^2, with its standard error
        inflated for the residuals' serial correlation), and the coefficients' scatter about a straight line in
        root distance is a chi-square on E - 2 degrees of freedom under "one law" (its p beside it). Conservative:
        the inflation for serial correlation (residual lag-1 autocorrelation ~0.96 in the pipeline) is large, and
        on simulated scattered resonances that lowered the held-out RMSE by 15 % it gave p = 1; the held-out
        test, not this statistic, judges the effect, and the explanation does not quote it."""
        R, k, z, s = ctx.R, ctx.kappa, ctx.z, ctx.s
        d2z = np.gradient(np.gradient(z))
        acc, se = per_edge_regression(R, k[:, None] * d2z[None, :])
        se = se * math.sqrt(ctx.inflation)
        ok = np.isfinite(acc) & np.isfinite(se) & (se > 0)
        chi2, dof = 0.0, max(int(ok.sum()) - 2, 0)
        if dof > 0:
            w = 1.0 / se[ok] ** 2
            X = np.stack([np.ones(ok.sum()), s[ok]], axis=1)
            beta = np.linalg.lstsq(X * np.sqrt(w)[:, None], acc[ok] * np.sqrt(w), rcond=None)[0]
            chi2 = float(np.sum(w * (acc[ok] - X @ beta) ** 2))
        p = float(special.chdtrc(dof, chi2)) if dof > 0 else 1.0
        return {"accel_coef_per_edge_frames2": np.where(ok, acc, 0.0), "accel_scatter_chi2": chi2,
                "accel_scatter_dof": float(dof), "accel_scatter_p": p}

    def longest_period_frames(self, state) -> float:
        """The longest natural period among the resonating joints (frames); :meth:`Dynamics.implausible` judges it."""
        return self.describe(state)["period_longest_frames"]

    def explain(self, summary: dict, statistics: dict) -> str:
        zeta = (summary.get("zeta") or {}).get("value") or float("nan")
        static = int(summary.get("quasi_static_joints", 0) or 0)
        text = (("" if not static else f"{static} joint{'s' if static > 1 else ''} quasi-static (no inertia the data "
                 "can see); ")
                + f"fitted natural periods from {summary.get('period_shortest_frames', float('nan')):.1f} to "
                f"{summary.get('period_longest_frames', float('nan')):.1f} frames (median "
                f"{summary.get('period_median_frames', float('nan')):.1f}), damping ratio {zeta:.2f} (each joint's "
                "period with its standard error is in the fit below).")
        return text[0].upper() + text[1:]
