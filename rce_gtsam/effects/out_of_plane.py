"""``out_of_plane``: the branch swings out of its plane, toward and away from the camera.

Physics (issue #39): each joint bends in the branch plane by kappa_e z_t and out of it by psi_e = kappa_e z_o(t)
(the same compliance: a round stem), z_o the out-of-plane share of the wind. Where the branch plane is tilted to
the camera, a segment's elevation out of the plane turns its image direction, so the 2-D bend angle reads

    y_e(t) = kappa_e z_t + g_e w_t,

w_t the swing's course (unit RMS) and g_e (deg per unit of w) what it adds to joint e's image angle. The part of
z_o that moves with z is absorbed by kappa; w is the rest, which the bend angles cannot tell from noise or from a
second excitation, but the segments' *lengths* can: a swing changes every segment's projected length, and a
course common to segments that share no tracked node is no tracker error
(:mod:`rce_gtsam.diagnosis.length_channel`). So w comes from the length channel, not from the bend angles, and
the term is per-edge coefficients on known courses: held out, it predicts the bending only where the swing is
real. The image angle's change with the elevation depends on the segment's heading, which moves with z, and a
large swing acts at second order, so the term has three courses (measured on the 2-D simulator's noise-free tracks
foreshortened by this model, a stand-in for the 3-D simulator, at share 0.5 and tilt 30 deg: the true z_o alone took the rank-1 misfit of 4
seeds from 0.27/0.46/0.36/0.21 deg RMS to 0.22/0.29/0.35/0.07, with z_o z and z_o^2 to 0.14/0.21/0.32/0.05):

    y_e(t) = kappa_e z_t + g_e w_t + h_e w_t z_t + q_e w_t^2.

The effect holds its data (the recording's :class:`~rce_gtsam.diagnosis.length_channel.LengthChannel` and the
course w computed from it with the baseline's excitation); without one (``OutOfPlane()``, the registry's default,
or a fit on a bend matrix alone) the term is zero and the diagnosis never names it. Its test is its own family at
its own level :data:`~rce_gtsam.diagnosis.length_channel.ALPHA_OOP` (the length channel is not one of the bend
residuals' statistics the other candidates share alpha over), so adding it leaves their Bonferroni count as it was;
a diagnosis' nominal family-wise false-alarm rate is alpha + ALPHA_OOP.
"""

from __future__ import annotations

import numpy as np

from .base import Effect, Parameter
from .offset import residual_variance_inflated, shrink_toward_zero


class OutOfPlane(Effect):
    """Out-of-plane swing read from the segments' lengths.

    channel: the recording's length channel (None: no data, the term stays zero); z: (T,) the baseline's
    excitation (deg) the course is computed with (needed with ``channel``)."""

    name = "out_of_plane"
    kind = "additive"
    equation = ("y_e(t) = kappa_e z_t + g_e w_t + h_e w_t z_t + q_e w_t^2, w the course the segments' lengths share "
                "beyond z")
    fitting = ("w (unit RMS) once from the length channel: the leading course of the segments' relative length "
               "changes after each is regressed on 1, t, z, z^2 and dz/dt; g_e, h_e, q_e per edge by weighted least "
               "squares of the partial residual on the centred courses w, w z, w^2, each shrunk toward 0 by "
               "empirical Bayes like the offsets")
    physics = ("the branch swings out of its plane, toward and away from the camera: segment lengths in the image "
               "change together with a course the in-plane bending does not explain, and in a branch plane tilted "
               "to the camera the swing turns the image angles, so the 2-D compliance mixes in-plane and "
               "out-of-plane bending. Measure it with depth (a RealSense recording), or film along the plane's "
               "normal with the wind across the view.")
    #: the diagnosis judges this effect by its own test at its own level (its own family, see the module docstring)
    own_family = True

    def __init__(self, channel=None, z: np.ndarray | None = None):
        self.channel = channel
        self._z = None if z is None else np.asarray(z, float)
        self._w: np.ndarray | None = None
        self._tests: dict = {}

    @property
    def available(self) -> bool:
        """Only with a length channel (and the excitation to compute the course with)."""
        return self.channel is not None and self._z is not None

    def __repr__(self) -> str:
        return "OutOfPlane()" if self.channel is None else f"OutOfPlane(<{len(self.channel.segments)} segments>)"

    # -- the course ---------------------------------------------------------------------------------
    def course(self, n_frames: int) -> np.ndarray:
        """(n_frames,) the swing course w (unit RMS; zeros without a channel or when the frames do not match)."""
        if self.channel is None or self._z is None or self.channel.rel.shape[1] != n_frames:
            return np.zeros(n_frames)
        if self._w is None:
            from ..diagnosis.length_channel import swing_course
            self._w = swing_course(self.channel, self._z)
        return self._w

    def length_test(self, seed: int = 0):
        """The length channel's test (:func:`~rce_gtsam.diagnosis.length_channel.out_of_plane_test`), or None
        without a channel; computed once per seed."""
        if self.channel is None or self._z is None:
            return None
        if seed not in self._tests:
            from ..diagnosis.length_channel import out_of_plane_test
            self._tests[seed] = out_of_plane_test(self.channel, self._z, seed=seed)
        return self._tests[seed]

    # -- the protocol -------------------------------------------------------------------------------
    def parameters(self, n_edges: int):
        return (Parameter("g", "deg", per_edge=True, description="bend angle per unit RMS of the swing course w"),
                Parameter("h", "deg", per_edge=True,
                          description="bend angle per unit RMS of w times the in-plane excitation z (the swing "
                                      "turns the image angle by an amount that depends on the segment's heading)"),
                Parameter("q", "deg", per_edge=True, description="bend angle per unit RMS of w^2 (second order)"))

    def courses(self, view) -> np.ndarray:
        """(3, T) the term's courses, each centred and unit RMS: w, w (z - mean z) with the view's current
        excitation z (held out: the one estimated from the other rows), and w^2. Zeros without a course."""
        w = self.course(view.T)
        if not np.any(w):
            return np.zeros((3, view.T))
        zc = view.z - np.mean(view.z)
        C = np.stack([w, w * zc, w * w])
        C = C - C.mean(axis=1, keepdims=True)
        return C / np.maximum(np.sqrt(np.mean(C * C, axis=1, keepdims=True)), 1e-300)

    def init(self, view) -> dict:
        st = {"params": {k: np.zeros(view.E) for k in "ghq"}, "latents": {}}
        return self.update(st, view, frozen=False)

    def update(self, state, view, frozen):
        if frozen:
            return state
        C = self.courses(view)
        E = view.E
        if not np.any(C):
            return {"params": {k: np.zeros(E) for k in "ghq"}, "latents": {}, "dof": 0.0}
        i = view.index_of(self)
        target = view.partial_target(i) if i is not None else view.Y0 - view.predict()
        W = view.W
        coef, var = np.zeros((E, 3)), np.full((E, 3), np.inf)
        resid = np.full(target.shape, np.nan)
        for e in range(E):
            ok = W[e] > 0
            if ok.sum() < 10:
                continue
            A = C[:, ok].T * np.sqrt(W[e, ok])[:, None]
            M = A.T @ A
            if np.linalg.matrix_rank(M) < 3:
                continue
            coef[e] = np.linalg.solve(M, A.T @ (target[e, ok] * np.sqrt(W[e, ok])))
            resid[e, ok] = target[e, ok] - coef[e] @ C[:, ok]
            var[e] = np.diag(np.linalg.inv(M))
        infl = residual_variance_inflated(resid, W)
        out, dof = {}, 0.0
        for j, k in enumerate("ghq"):
            with np.errstate(invalid="ignore"):  # an edge without a fit has var inf; no residual at all: infl nan
                v = infl * var[:, j]
            out[k], f = shrink_toward_zero(coef[:, j], v)
            dof += float(f.sum())
        return {"params": out, "latents": {}, "dof": dof}

    def n_free(self, state, n_edges, n_frames_observed):
        """The shrunk coefficients' effective degrees of freedom (the sum of their shrinkage factors)."""
        dof = state.get("dof")
        return super().n_free(state, n_edges, n_frames_observed) if dof is None else float(dof)

    def additive(self, state, view):
        p = state["params"]
        G = np.stack([p["g"], p["h"], p["q"]], axis=1)
        return G @ self.courses(view)

    def describe(self, state):
        p = state["params"]
        g = np.sqrt(p["g"] ** 2 + p["h"] ** 2 + p["q"] ** 2)
        return {"rms_swing_bend_deg": float(np.sqrt(np.mean(g ** 2))) if g.size else 0.0,
                "has_length_channel": self.channel is not None}

    def evidence(self, ctx) -> dict:
        """The length channel's test (p, statistic against its null's median, the loadings' sign and growth toward
        the tip), and the bend residuals' regression on the course w: {} without a length channel."""
        test = self.length_test()
        if test is None:
            return {}
        w = self.course(ctx.R.shape[1])
        ok = np.isfinite(ctx.R)
        R0 = np.where(ok, ctx.R, 0.0)
        sww = (ok * w[None, :] ** 2).sum(axis=1)
        g = (R0 * w[None, :]).sum(axis=1) / np.maximum(sww, 1e-12)
        return {"length_p": test.p, "length_statistic": test.statistic, "length_null_median": test.null_median,
                "length_same_sign_share": test.same_sign_share, "length_tip_growth": test.tip_growth,
                "length_agreement": test.agreement, "length_agreement_p": test.agreement_p,
                "length_heldout_gain_pct": test.heldout_gain_pct,
                "rms_residual_on_course_deg": float(np.sqrt(np.mean(g ** 2)))}

    @classmethod
    def for_analysis(cls, result) -> "OutOfPlane":
        """The term with the recording's length channel and the analysis' excitation (its rank-1 fit's z, the
        diagnosis baseline's); without data where the fit has no excitation over the response's frames."""
        from ..diagnosis.length_channel import length_channel_of
        z = getattr(result.fit, "z", None)
        if z is None or len(z) != result.response.Y.shape[1]:
            return cls()
        return cls(length_channel_of(result), z)

    def own_family_test(self, fit, seed: int = 0) -> dict | None:
        """The diagnosis' test of this effect, its own family: {"p", "alpha", ...} or None (no length channel, or
        too few segments for two node-disjoint sets). ``fit``: the rank-1 baseline (unused: the course and the test
        use the excitation the effect was made with, the same baseline's)."""
        from ..diagnosis.length_channel import ALPHA_OOP
        from ..diagnosis.swing_signature import ALPHA_AGREE
        test = self.length_test(seed)
        if test is None:
            return None
        return {"p": test.p, "alpha": ALPHA_OOP, "agreement_alpha": ALPHA_AGREE,
                "heldout_gain_pct": test.heldout_gain_pct, **test.as_dict()}

    def explain(self, summary: dict, statistics: dict) -> str:
        return (f"The segments' lengths in the image share a course beyond the in-plane bending (length-channel "
                f"test p = {statistics.get('length_p', float('nan')):.3g}, statistic "
                f"{statistics.get('length_statistic', 0):.1f} against a null median "
                f"{statistics.get('length_null_median', 0):.1f}; {100 * statistics.get('length_same_sign_share', 0):.0f} % "
                f"of the segments change with one sign, rank correlation of the change with root distance "
                f"{statistics.get('length_tip_growth', 0):+.2f}; neighbouring segments' loadings agree at "
                f"{statistics.get('length_agreement', 0):+.2f}, p = {statistics.get('length_agreement_p', 1.0):.2g} "
                f"against node parts: a swing adds up from the root); predicting each segment's held-out frames from "
                f"the course of the segments it shares no node with lowers their length error by "
                f"{statistics.get('length_heldout_gain_pct', float('nan')):.1f} %; that course adds "
                f"{statistics.get('rms_residual_on_course_deg', 0):.2f} deg RMS to the bend residuals.")

