"""``dynamics``: segments have inertia and respond as damped oscillators.

Physics: each edge's deflection follows a damped second-order response to its quasi-static load
kappa_e z:   y'' + 2 zeta omega_e y' + omega_e^2 y = omega_e^2 kappa_e z   (time in frames, omega in
rad/frame, static gain 1). Stiff, light proximal segments have high natural frequencies (quasi-static);
distal ones resonate lower, lag and ring after gusts. The natural frequency varies along the branch as
log omega_e = (1 - s_e) log omega_root + s_e log omega_tip (s_e: root distance 0..1); zeta is shared.
A filter common to all edges is absorbed by z, so only the variation along the branch is identifiable.
Discretised exactly for an input linear between frames (first-order hold); each edge starts at rest at
the static response to the first frame's load.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import signal
from scipy.linalg import expm
from scipy.optimize import least_squares

from .base import Effect, Parameter, scalar
from .delay import _sse_after_z
from .offset import _index

OMEGA_MIN, OMEGA_MAX = 0.05, 2 * np.pi  # rad/frame: a period of ~125 frames .. 1 frame (quasi-static)
ZETA_MIN, ZETA_MAX = 0.03, 2.0


@lru_cache(maxsize=4096)
def _coeffs(omega: float, zeta: float, T: int):
    """lfilter (b, a) of the oscillator discretised with a first-order hold, and its free response from a
    unit steady state. Same equations as ``scipy.signal.cont2discrete(method="foh")`` (augmented matrix
    exponential), written out for the 2-state case because the generic routine costs ~10 ms per call."""
    A = np.array([[0.0, 1.0], [-omega * omega, -2.0 * zeta * omega]])
    em = np.zeros((4, 4))
    em[:2, :2] = A
    em[:2, 2] = [0.0, omega * omega]
    em[2, 3] = 1.0
    ms = expm(em)
    ad, m12, m13 = ms[:2, :2], ms[:2, 2], ms[:2, 3]
    bd = m12 - m13 + ad @ m13
    dd = m13[0]  # C = [1, 0], D = 0
    a = np.array([1.0, -(ad[0, 0] + ad[1, 1]), ad[0, 0] * ad[1, 1] - ad[0, 1] * ad[1, 0]])
    b = dd * a + np.array([0.0, bd[0], -ad[1, 1] * bd[0] + ad[0, 1] * bd[1]])
    zi = signal.lfilter_zi(b, a)
    free_resp = signal.lfilter(b, a, np.zeros(T), zi=zi)[0]  # response to a unit initial steady state
    return b, a, free_resp


class Dynamics(Effect):
    """Per-edge damped 2nd-order response with natural frequency log-linear in root distance."""

    name = "dynamics"
    kind = "operator"
    equation = ("y_e'' + 2 zeta w_e y_e' + w_e^2 y_e = w_e^2 kappa_e z,  "
                "log w_e = (1 - s_e) log w_root + s_e log w_tip   (w in rad/frame)")
    fitting = ("(log w_root, log w_tip, zeta) by bounded least squares (scipy.optimize.least_squares) with "
               "kappa and z fixed, alternating with the core; started from the best of a grid")

    def parameters(self, n_edges: int):
        return (Parameter("omega_root", "rad/frame", OMEGA_MIN, OMEGA_MAX, description="natural frequency at the root"),
                Parameter("omega_tip", "rad/frame", OMEGA_MIN, OMEGA_MAX, description="natural frequency at the tip"),
                Parameter("zeta", "1", ZETA_MIN, ZETA_MAX, description="damping ratio"))

    @staticmethod
    def omegas(state, s):
        p = state["params"]
        lr, lt = np.log(scalar(p["omega_root"])), np.log(scalar(p["omega_tip"]))
        return np.exp((1 - s) * lr + s * lt)

    def _filters(self, state, view):
        om = self.omegas(state, view.s)
        zeta = scalar(state["params"]["zeta"])
        return [_coeffs(round(float(w), 10), round(zeta, 10), view.T) for w in om]

    def apply(self, X, state, view):
        out = np.empty_like(X)
        for e, (b, a, fr) in enumerate(self._filters(state, view)):
            out[e] = signal.lfilter(b, a, X[e]) + X[e, 0] * fr
        return out

    def apply_T(self, R, state, view):
        out = np.empty_like(R)
        for e, (b, a, fr) in enumerate(self._filters(state, view)):
            out[e] = signal.lfilter(b, a, R[e][::-1])[::-1]
            out[e, 0] += float(np.dot(fr, R[e]))
        return out

    @staticmethod
    def _state(p):
        return {"params": {"omega_root": np.array(np.exp(p[0])), "omega_tip": np.array(np.exp(p[1])),
                           "zeta": np.array(p[2])}, "latents": {}}

    def init(self, view) -> dict:
        i = len(view.states)
        best, best_err = None, np.inf
        # quasi-static start first, then a grid of tip frequencies and root/tip ratios (zeta 0.2)
        cands = [(OMEGA_MAX, OMEGA_MAX, 0.7)]
        for wt in (0.15, 0.25, 0.4, 0.7, 1.2):
            for ratio in (1.5, 3.0, 6.0):
                cands.append((min(wt * ratio, OMEGA_MAX), wt, 0.2))
        for wr, wt, zt in cands:
            st = self._state((np.log(wr), np.log(wt), zt))
            err = _sse_after_z(view, i, st)
            if err < best_err:
                best, best_err = st, err
        return best

    def update(self, state, view, frozen):
        if frozen:
            return state
        i = _index(self, view)
        p = state["params"]
        lo = [np.log(OMEGA_MIN), np.log(OMEGA_MIN), ZETA_MIN]
        hi = [np.log(OMEGA_MAX), np.log(OMEGA_MAX), ZETA_MAX]
        x0 = np.clip([np.log(scalar(p["omega_root"])), np.log(scalar(p["omega_tip"])), scalar(p["zeta"])],
                     np.array(lo) + 1e-6, np.array(hi) - 1e-6)
        res = least_squares(lambda q: view.residual_vector(i, self._state(q)), x0, bounds=(lo, hi),
                            diff_step=1e-4, max_nfev=3)
        return self._state(res.x)

    def describe(self, state):
        p = state["params"]
        return {"period_root_frames": float(2 * np.pi / scalar(p["omega_root"])),
                "period_tip_frames": float(2 * np.pi / scalar(p["omega_tip"]))}
