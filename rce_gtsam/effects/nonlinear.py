"""``nonlinear``: the response is not proportional to the load at large deflections.

Physics: each joint's deflection is a saturating (or, for ``form="cubic"``, possibly softening) odd
function of its linear response u_e = kappa_e x_e:
  saturation  y_e = y_s tanh(u_e / y_s)  — large-deflection stiffening: the joint "runs out" of bending,
              parametrised by the curvature c = 1 / y_s^2 >= 0 (deg^-2; c = 0 is linear);
  cubic       y_e = u_e - c u_e^3 / 3   — the first-order expansion of either stiffening (c > 0) or
              softening (c < 0).
The map acts on each joint's own deflection, so compliant joints saturate more (a shared saturation of z
would be rank 1 and invisible). The joints saturate about their unloaded rest, but bending is measured from a
reference pose (the median angle): y_e = g(kappa_e (z + z0)) - g(kappa_e z0), with z0 the excitation at that
pose (one shared number). Without z0 the saturation is off-centre by up to a degree on simulated branches and
the fit finds no curvature at all, even on noise-free tracks (c 7e-11 against the true 0.44 deg^-2).
Units: c in deg^-2; y_s, z0 in degrees.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..model.steps import core_step
from ..model.tangent import remove_rank1_tangent
from .base import Effect, Parameter, scalar


GRID_CORE_STEPS = 4  # kappa and z steps per grid point before the errors are compared
# per-edge gain multipliers tried in each update (log-spaced, 1/64 to 64, then refined around each edge's best):
# an edge deep in saturation at the reference pose has a second, shallow minimum of its error at a small
# linear gain, far from (and much wider than) the true one (noise-free simulated branch: the true gain 31x the
# fitted one), which the Gauss-Newton kappa step cannot leave
KAPPA_SCAN = 2.0 ** np.arange(-6.0, 6.25, 0.25)
KAPPA_REFINE = 2.0 ** np.linspace(-0.25, 0.25, 9)
REFINE_ROUNDS = 2  # rounds of the finer local grid around the coarse grid's best (c, z0)


def best_edge_gains(view) -> np.ndarray:
    """kappa with each edge's gain replaced by the best of :data:`KAPPA_SCAN` x its gain, refined by
    :data:`KAPPA_REFINE` (everything else fixed; the current gain is one of the candidates).

    Given z and the shared (c, z0), each edge's error depends on its own kappa_e only, so the scan is exact per
    edge: a global 1-D search where the Gauss-Newton step only finds the nearest minimum."""
    def best(mults):  # mults: (M, E) multipliers per edge -> (E,) the best
        sse = np.empty(mults.shape)
        for j, m in enumerate(mults):
            r = view.Y0 - view.predict(kappa=view.kappa * m)
            sse[j] = np.sum(view.W * r * r, axis=1)
        return mults[np.argmin(sse, axis=0), np.arange(mults.shape[1])]

    E = view.kappa.size
    coarse = best(np.repeat(KAPPA_SCAN[:, None], E, axis=1))
    return view.kappa * best(np.concatenate([coarse[None] * KAPPA_REFINE[:, None], np.ones((1, E))]))


class Nonlinear(Effect):
    """Shared odd output nonlinearity g(kappa_e x_e); form ``"saturation"`` (tanh) or ``"cubic"``."""

    name = "nonlinear"
    kind = "output"
    #: Both tests must agree (fold t and the curvature score test, each at its share of alpha). Measured: the
    #: rank-1 model's excitation absorbs most of a saturation — with q / y_s at 3x, 10x and 30x the simulator's
    #: default, the baseline residual's odd bend against the prediction stays |t| < 0.6 (14 recordings), and the
    #: oracle with the true saturation passes the verdict's test on 0 of 14 (450 and 900 frames, x3) — while on
    #: the user's path (our tracker on rendered effect-free video) one test alone named a saturation on 5 of 80
    #: recordings (fold t 3.1-4.5 with score p 0.04-0.44; score p 0.002 with fold t 2.0), never both.
    needs_both_tests = True
    fitting = ("c by bounded least squares (scipy.optimize.least_squares) with kappa and z fixed, "
               "alternating with Gauss-Newton core steps; started from the best of a grid")
    physics = ("the response is not proportional to the load at large deflections: compliant joints saturate "
               "(stiffen) during strong gusts, so one linear gain per joint over-predicts the peaks. Kappa is then "
               "the small-deflection gain, and the saturation angle says where linear compliance stops being a "
               "good description.")

    def __init__(self, form: str = "saturation"):
        if form not in ("saturation", "cubic"):
            raise ValueError(f"form must be 'saturation' or 'cubic', got {form!r}")
        self.form = form

    @property
    def equation(self):  # type: ignore[override]
        g = "y_s tanh(u / y_s),  c = 1/y_s^2" if self.form == "saturation" else "u - c u^3 / 3"
        return f"y_e = g(kappa_e (z + z0)) - g(kappa_e z0),  g(u) = {g}"

    def __repr__(self) -> str:
        return f"Nonlinear(form={self.form!r})"

    def parameters(self, n_edges: int):
        lo = 0.0 if self.form == "saturation" else -np.inf
        return (Parameter("c", "deg^-2", lo, np.inf, description="curvature 1/y_s^2 of the response"),
                Parameter("z0", "deg", description="excitation at the reference pose the bending is measured "
                                                   "from, relative to the unloaded rest the joints saturate about"))

    def _g(self, U, c):
        """g(U) and g'(U) elementwise."""
        if self.form == "cubic":
            return U - c * U ** 3 / 3.0, 1.0 - c * U * U
        if c <= 0:
            return U, np.ones_like(U)
        k = np.sqrt(c)
        th = np.tanh(k * U)
        return th / k, 1.0 - th * th

    def _reference(self, state, kappa):
        """(E, 1) linear deflection kappa_e z0 of the reference pose, or None (z0 = 0 or no kappa)."""
        z0 = scalar(state["params"].get("z0", 0.0))
        if kappa is None or z0 == 0.0:
            return None
        return np.asarray(kappa, dtype=float)[:, None] * z0

    def output(self, U, state, kappa=None):
        """The joints saturate about their unloaded rest, but the pipeline measures bending from a reference
        pose (the median angle, or the first frame): g is centred at the rest, which the shared z0 places,
        and the reference's own deflection g(kappa_e z0) is subtracted (one number: the reference is a pose
        of the whole branch under one excitation z0)."""
        c = scalar(state["params"]["c"])
        U0 = self._reference(state, kappa)
        if U0 is None:
            return self._g(U, c)
        G, dG = self._g(U + U0, c)
        return G - self._g(U0, c)[0], dG

    def rescale_z(self, state, factor):
        """z0 is in units of z: kappa (z + z0) must not change when the model normalises kappa."""
        if "z0" not in state["params"]:
            return state
        return {**state, "params": {**state["params"], "z0": np.array(scalar(state["params"]["z0"]) * factor)}}

    def output_kappa_term(self, dG, state, kappa):
        U0 = self._reference(state, kappa)
        if U0 is None:
            return 0.0
        z0 = scalar(state["params"]["z0"])
        return z0 * (dG - self._g(U0, scalar(state["params"]["c"]))[1])

    def init(self, view) -> dict:
        i = len(view.states)
        U = view.kappa[:, None] * view.transform(view.z)
        q = float(np.quantile(np.abs(U[view.W > 0]), 0.99)) if (view.W > 0).any() else 1.0
        q = max(q, 1e-6)
        zq = float(np.quantile(np.abs(view.z), 0.99)) if view.z.size else 1.0
        zq = max(zq, 1e-6)
        grid = [0.0] + [1.0 / (k * q) ** 2 for k in (4.0, 2.0, 1.0, 0.6)]
        if self.form == "cubic":
            grid += [-g for g in grid[1:3]]
        model = getattr(view, "full_model", view.model)
        sub = model.with_effects(model.effects[: i + 1])
        scores: dict = {}

        def score(c, z0):
            """wsse after a few core steps at (c, z0), and the kappa and z they reached (cached)."""
            key = (round(c * q * q, 9), round(z0 / zq, 9))
            if key not in scores:
                # a saturating g needs a larger linear deflection underneath than the linear fit found: a few
                # kappa and z steps per grid point let kappa * z grow into it before the errors are compared
                v = view.copy_with(sub, list(view.states)[:i] + [{"params": {"c": np.array(c), "z0": np.array(z0)},
                                                                   "latents": {}}])
                for _ in range(GRID_CORE_STEPS):
                    core_step(v)
                scores[key] = (v.wsse(), (c, z0), (v.kappa.copy(), v.z.copy()))
            return scores[key]

        for c in grid:
            for z0 in ((0.0,) if c == 0.0 else (0.0, -0.5 * zq, 0.5 * zq, -zq, zq)):
                score(c, z0)
        # the error surface in (c, z0) is a curved valley: refine around the coarse grid's best point (finer
        # steps in both), which the alternating steps from a coarse point do not reach (noise-free simulated
        # branch: fit RMSE 0.026 -> 0.007 deg, c 0.19 -> 0.36 against the true 0.38 deg^-2)
        for _ in range(REFINE_ROUNDS):
            c_best, z_best = min(scores.values(), key=lambda r: r[0])[1]
            if c_best <= 0:
                break
            for f in (0.5, 0.7, 1.0, 1.4, 2.0):
                for dz in (-0.25, 0.0, 0.25):
                    score(c_best * f, z_best + dz * zq)
        _, best, best_core = min(scores.values(), key=lambda r: r[0])
        # the fit goes on from the grid point's own kappa and z: the linear fit's kappa and z are compressed by
        # the saturation (compliant joints most), and from them the alternating steps settle at a shallower
        # curvature (noise-free branch: fit RMSE 0.024 deg from the linear start, 0.019 from the grid's)
        return {"params": {"c": np.array(best[0]), "z0": np.array(best[1])}, "latents": {}, "scale": q,
                "z_scale": zq, "core_start": best_core if best[0] > 0 else None}

    def update(self, state, view, frozen):
        if frozen:
            return state
        i = view.index_of(self)
        q = state.get("scale", 1.0)
        zq = state.get("z_scale", 1.0)
        unit = 1.0 / q ** 2  # optimise c in units of 1/q^2 and z0 in units of z's scale: a well-scaled problem
        lo = 0.0 if self.form == "saturation" else -np.inf
        x0 = [max(scalar(state["params"]["c"]) / unit, lo), scalar(state["params"].get("z0", 0.0)) / zq]

        def st_of(p):
            return {"params": {"c": np.array(p[0] * unit), "z0": np.array(p[1] * zq)}, "latents": {}}

        res = least_squares(lambda p: view.residual_vector(i, st_of(p)), x0, bounds=([lo, -np.inf], [np.inf, np.inf]),
                            diff_step=1e-3, max_nfev=12, x_scale=[1.0, 1.0])
        new = {**st_of(res.x), "scale": q, "z_scale": zq}
        if scalar(new["params"]["c"]) != 0.0:
            gains = best_edge_gains(view.copy_with(view.model, view.with_state(i, new)))
            if not np.array_equal(gains, view.kappa):
                new["core_start"] = (gains, view.z.copy())
        return new

    def score_directions(self, kappa, z, s):
        """To first order in c the map moves kappa_e z_t by -c/3 kappa_e^3 ((z + z0)^3 - z0^3) = -c/3 kappa_e^3 (z^3 +
        3 z0 z^2 + 3 z0^2 z); the last term is a change of kappa_e, so two directions: kappa_e^3 z^3 (the odd,
        symmetric saturation) and kappa_e^3 z^2 (its offset from the reference pose). Units deg^3 and deg^2 per
        unit z."""
        k3 = np.asarray(kappa, float)[:, None] ** 3
        z = np.asarray(z, float)[None, :]
        return np.stack([k3 * z ** 3, k3 * z ** 2])

    def test_directions(self, kappa, z, s):
        """:meth:`score_directions` with what a rank-1 model built from this ``z`` could absorb removed first:
        each row's mean, then the least-squares part a_e z_t + kappa_e b_t (unit weights). A cube of z is mostly z
        itself, and the score test removes that part with the tested rows' own fit, whose excitation carries
        their noise: what it left of the large rank-1 part correlated with the residuals, and effect-free pipeline
        recordings (default preset, 900 frames, 40 seeds) gave p <= 0.005 on 11 of 40; removed here first, with
        the other row set's excitation, 0 of 40. Saturation at the simulator's default strength (10 seeds):
        p <= 0.005 on 2 of 10, the oracle along the true signature on 3 of 10. Quadratic over the two."""
        G = self.score_directions(kappa, z, s)
        G = G - G.mean(axis=2, keepdims=True)
        unit = np.ones(G.shape[1:])
        return remove_rank1_tangent(G, np.asarray(kappa, float), np.asarray(z, float), unit), "quadratic"

    def describe(self, state):
        c = scalar(state["params"]["c"])
        return {"saturation_deg": float(1 / np.sqrt(c)) if c > 0 else float("inf"),
                "reference_excitation_deg": scalar(state["params"].get("z0", 0.0))}

    def evidence(self, ctx) -> dict:
        """Curvature of the residual against the prediction: an odd cubic term (per-edge scaled, orthogonal
        to the linear one) with its AR(1)-inflated t statistic, and the even quadratic term."""
        R, k, z = ctx.R, ctx.kappa, ctx.z
        P = k[:, None] * z[None, :]
        q = np.nanquantile(np.abs(P), 0.99) if np.isfinite(P).any() else 1.0
        u = P / max(q, 1e-12)
        X3 = u ** 3 - u * (np.nansum(u ** 4, axis=1, keepdims=True)
                           / np.maximum(np.nansum(u ** 2, axis=1, keepdims=True), 1e-300))
        ok = np.isfinite(R)
        c3 = float(np.sum(X3[ok] * R[ok]) / max(np.sum(X3[ok] ** 2), 1e-300))
        res = R[ok] - c3 * X3[ok]
        se3 = np.sqrt(float(np.sum(res ** 2)) / max(ok.sum() - 1, 1) * ctx.inflation
                      / max(np.sum(X3[ok] ** 2), 1e-300))
        X2 = u ** 2 - np.nanmean(u ** 2, axis=1, keepdims=True)
        c2 = float(np.sum(X2[ok] * R[ok]) / max(np.sum(X2[ok] ** 2), 1e-300))
        return {"cubic_residual_at_q99_deg": c3, "cubic_t": c3 / max(float(se3), 1e-300),
                "quadratic_residual_at_q99_deg": c2, "q99_deflection_deg": float(q)}

    def implausible(self, state, ctx):
        """A saturation angle beyond ``ctx.saturation_reach`` times the largest deflection seen: the curve is
        straight over every deflection the record holds, so no saturation was observed."""
        sat = self.describe(state)["saturation_deg"]
        q = ctx.q99_deflection_deg
        if self.form == "saturation" and np.isfinite(q) and q > 0 and sat > ctx.saturation_reach * q:
            return [f"its saturation angle {sat:.3g} deg lies beyond {ctx.saturation_reach:g} x the largest "
                    f"deflection seen ({q:.3g} deg, 99th percentile): the response is straight over every "
                    f"deflection the record holds"]
        return []

    def explain(self, summary: dict, statistics: dict) -> str:
        sat = summary.get("saturation_deg", float("nan"))
        return (f"Saturation angle {sat:.2f} deg (99th percentile of the linear deflection "
                f"{statistics.get('q99_deflection_deg', float('nan')):.2f} deg); the baseline residual bends against "
                f"the prediction by {statistics.get('cubic_residual_at_q99_deg', 0):.3f} deg at that deflection "
                f"(t = {statistics.get('cubic_t', 0):.1f}).")
