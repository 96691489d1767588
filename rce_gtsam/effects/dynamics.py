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
from scipy.optimize import least_squares

import math

from ..diagnosis.statistics import per_edge_regression, slope_vs
from ..model.steps import sse_after_z
from .base import Effect, Parameter, scalar

OMEGA_MIN, OMEGA_MAX = 0.05, 2 * np.pi  # rad/frame: a period of ~125 frames .. 1 frame (quasi-static)
ZETA_MIN, ZETA_MAX = 0.03, 2.0
#: damping ratios the fit is restarted from (:meth:`Dynamics.alternative_starts`): half a decade apart, from
#: lightly damped to critically damped
ZETA_STARTS = (0.1, 0.3, 1.0)


def _foh_coeffs(omega: np.ndarray, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """lfilter (b, a) rows (E, 3) of the oscillator discretised with a first-order hold, for every omega.

    The same equations as ``scipy.signal.cont2discrete(method="foh")`` (augmented matrix exponential of
    [[A, B, 0], [0, 0, 1], [0, 0, 0]]), written in closed form for the 2-state system so that all edges
    are computed at once: Phi = e^A by the 2x2 formula e^(mu) [cosh(d) I + sinh(d)/d (A - mu I)],
    mu = -zeta omega, d = sqrt(mu^2 - omega^2) (complex when under-damped), and the hold integrals
    M12 = A^-1 (Phi - I) B, M13 = M12 - (A^-1 Phi - A^-2 (Phi - I)) B (A invertible: omega > 0)."""
    w = np.asarray(omega, dtype=float)
    E = w.size
    A = np.zeros((E, 2, 2))
    A[:, 0, 1] = 1.0
    A[:, 1, 0] = -w * w
    A[:, 1, 1] = -2.0 * zeta * w
    mu = -zeta * w
    d = np.sqrt((mu * mu - w * w).astype(complex))
    small = np.abs(d) < 1e-8
    sinhc = np.where(small, 1.0 + d * d / 6.0, np.sinh(d) / np.where(small, 1.0, d))
    I2 = np.eye(2)[None]
    Phi = np.real(np.exp(mu)[:, None, None] * (np.cosh(d)[:, None, None] * I2
                                               + sinhc[:, None, None] * (A - mu[:, None, None] * I2)))
    Ainv = np.zeros((E, 2, 2))
    Ainv[:, 0, 0] = -2.0 * zeta / w
    Ainv[:, 0, 1] = -1.0 / (w * w)
    Ainv[:, 1, 0] = 1.0
    B = np.stack([np.zeros(E), w * w], axis=1)[..., None]  # (E, 2, 1)
    PmI = Phi - I2
    M12 = Ainv @ PmI @ B
    M13 = M12 - (Ainv @ Phi - Ainv @ Ainv @ PmI) @ B
    bd = (M12 - M13 + Phi @ M13)[..., 0]
    dd = M13[:, 0, 0]
    a = np.stack([np.ones(E), -(Phi[:, 0, 0] + Phi[:, 1, 1]),
                  Phi[:, 0, 0] * Phi[:, 1, 1] - Phi[:, 0, 1] * Phi[:, 1, 0]], axis=1)
    b = dd[:, None] * a + np.stack([np.zeros(E), bd[:, 0], -Phi[:, 1, 1] * bd[:, 0] + Phi[:, 0, 1] * bd[:, 1]],
                                   axis=1)
    return b, a


def conv_length(T: int) -> int:
    """FFT length of the filters' linear convolution over T frames: the smallest 2^a 3^b 5^c >= 2T - 1 (any
    length from 2T - 1 on is exact; a prime factor such as 59 in 2T = 1180, plant 2's 590 frames, makes each
    FFT ~2x slower, and these FFTs are most of a dynamics fit's time)."""
    from scipy.fft import next_fast_len

    return next_fast_len(2 * T - 1, real=True)


@lru_cache(maxsize=256)
def _impulse(omegas: tuple, zeta: float, T: int) -> np.ndarray:
    """(E, T) impulse response h_e of every edge's filter over a record of T frames (lfilter)."""
    b, a = _foh_coeffs(np.array(omegas), zeta)
    imp = np.zeros(T)
    imp[0] = 1.0
    return np.stack([signal.lfilter(b[e], a[e], imp) for e in range(len(omegas))])


@lru_cache(maxsize=256)
def _bank(omegas: tuple, zeta: float, T: int):
    """Per-edge filters over a record of T frames: (free responses (E, T), frequency responses
    (E, conv_length(T) // 2 + 1)).

    The filter is applied as a linear convolution with the impulse response h_e (:func:`_impulse`) through
    zero-padded FFTs of :func:`conv_length` (exact, and one batched FFT for all edges). The free response from
    a unit initial steady state is 1 - cumsum(h_e): static gain 1 means the steady state minus the step
    response."""
    h = _impulse(omegas, zeta, T)
    return 1.0 - np.cumsum(h, axis=1), np.fft.rfft(h, conv_length(T), axis=1)


@lru_cache(maxsize=64)
def _spectrum(omegas: tuple, zeta: float, T: int, n_fft: int) -> np.ndarray:
    """(E, n_fft // 2 + 1) rfft of the impulse responses on a grid of length ``n_fft`` (the z step's
    preconditioner asks for 2T)."""
    return np.fft.rfft(_impulse(omegas, zeta, T), n_fft, axis=1)


class Dynamics(Effect):
    """Per-edge damped 2nd-order response with natural frequency log-linear in root distance."""

    name = "dynamics"
    kind = "operator"
    equation = ("y_e'' + 2 zeta w_e y_e' + w_e^2 y_e = w_e^2 kappa_e z,  "
                "log w_e = (1 - s_e) log w_root + s_e log w_tip   (w in rad/frame)")
    fitting = ("(log w_root, log w_tip, zeta) by bounded least squares (scipy.optimize.least_squares) with "
               "kappa and z fixed, alternating with the core; started from the best of a grid")
    physics = ("the segments do not follow the wind quasi-statically: they have inertia and resonate (distal "
               "segments at a lower natural frequency), so they lag, amplify near resonance and ring after gusts. "
               "Kappa is then the static (low-frequency) gain; the natural frequencies are a mechanical property "
               "of the plant.")
    # the smoother attenuates curvature most where tracking is noisiest (toward the tip), a kappa_e s_e d2z/dt2
    # signature of its own: with the full fit's own z and a refitted null this test called 16/40 effect-free
    # pipeline seeds significant at p = 0.005; each row set's directions from the other set's z: 0/40
    score_excitation = "other_rows"

    #: a natural frequency at its top bound (a period of ~1 frame) is a quasi-static joint, and one at its bottom
    #: bound a period as long as the search reaches (~125 frames): a slow inertia, still a lag; neither is an edge
    #: of the form (measured: a 3x default inertia, tip period 117 frames, fits at the bottom bound)
    natural_limits = {"omega_root": ("upper", "lower"), "omega_tip": ("upper", "lower")}

    def parameters(self, n_edges: int):
        return (Parameter("omega_root", "rad/frame", OMEGA_MIN, OMEGA_MAX, description="natural frequency at the root"),
                Parameter("omega_tip", "rad/frame", OMEGA_MIN, OMEGA_MAX, description="natural frequency at the tip"),
                Parameter("zeta", "1", ZETA_MIN, ZETA_MAX, description="damping ratio"))

    @staticmethod
    def omegas(state, s):
        p = state["params"]
        lr, lt = np.log(scalar(p["omega_root"])), np.log(scalar(p["omega_tip"]))
        return np.exp((1 - s) * lr + s * lt)

    def _key(self, state, view) -> tuple:
        """(omegas, zeta, T): the cache key of every edge's filter."""
        om = np.round(np.asarray(self.omegas(state, view.s), float), 12)  # one vectorised rounding per call
        return tuple(om.tolist()), round(scalar(state["params"]["zeta"]), 12), view.T

    def _stack(self, state, view):
        """(free responses (E, T), frequency responses (E, conv_length(T) // 2 + 1)) of every edge's filter."""
        return _bank(*self._key(state, view))

    def apply(self, X, state, view):
        # the filter as a convolution with its impulse response, all edges in one FFT (exact: zero padding
        # to at least 2T - 1 makes it linear), plus the free response of the initial steady state x[0]
        T = X.shape[1]
        L = conv_length(T)
        fr, Hf = self._stack(state, view)
        # z broadcast to every edge (the usual input, FitView.transform): one forward FFT, not one per edge
        Xf = np.fft.rfft(X[0], L)[None, :] if X.strides[0] == 0 else np.fft.rfft(X, L, axis=1)
        return np.fft.irfft(Xf * Hf, L, axis=1)[:, :T] + X[:, :1] * fr

    def _adjoint(self, R, state, view):
        """(the rows' adjoint spectra rfft(r_e) conj(H_e) (E, L // 2 + 1), the free responses times R (E, T), whose
        sum goes to frame 0, L): what :meth:`apply_T` and :meth:`apply_T_sum` transform back and sum."""
        L = conv_length(R.shape[1])
        fr, Hf = self._stack(state, view)
        return np.fft.rfft(R, L, axis=1) * np.conj(Hf), fr * R, L

    def apply_T(self, R, state, view):
        spectra, free, L = self._adjoint(R, state, view)
        out = np.fft.irfft(spectra, L, axis=1)[:, :R.shape[1]]
        out[:, 0] += np.sum(free, axis=1)
        return out

    def apply_T_sum(self, R, state, view):
        # the sum over edges taken in the frequency domain: one inverse FFT instead of one per edge
        spectra, free, L = self._adjoint(R, state, view)
        out = np.fft.irfft(np.sum(spectra, axis=0), L)[:R.shape[1]]
        out[0] += float(np.sum(free))
        return out

    def transfer(self, state, view, n_fft: int):
        """Frequency response of each edge's filter on the rfft grid of length ``n_fft`` (E, n_fft//2 + 1)."""
        key = self._key(state, view)
        return _bank(*key)[1] if n_fft == conv_length(view.T) else _spectrum(*key, n_fft)

    @staticmethod
    def _state(p):
        return {"params": {"omega_root": np.array(np.exp(p[0])), "omega_tip": np.array(np.exp(p[1])),
                           "zeta": np.array(p[2])}, "latents": {}}

    def init(self, view) -> dict:
        i = len(view.states)
        best, best_err = None, np.inf
        # quasi-static start first, then a grid of tip frequencies and root/tip ratios (zeta 0.2); the grid spans
        # the whole bounded range down to OMEGA_MIN: the few least-squares steps per update cannot walk from a
        # tip period of 40 frames to one of 100 (simulated 2-3x default dynamics, tip periods 78-117 frames:
        # with the grid starting at 0.15 rad/frame the fit stayed there and lost 6-9 % held-out RMSE against the
        # baseline while the true parameters gained 20 %)
        cands = [(OMEGA_MAX, OMEGA_MAX, 0.7)]
        for wt in (0.06, 0.1, 0.15, 0.25, 0.4, 0.7, 1.2):
            for ratio in (1.5, 3.0, 6.0):
                cands.append((min(wt * ratio, OMEGA_MAX), wt, 0.2))
        for wr, wt, zt in cands:
            st = self._state((np.log(wr), np.log(wt), zt))
            err = sse_after_z(view, i, st)
            if err < best_err:
                best, best_err = st, err
        return best

    def update(self, state, view, frozen):
        if frozen:
            return state
        i = view.index_of(self)
        p = state["params"]
        lo = [np.log(OMEGA_MIN), np.log(OMEGA_MIN), ZETA_MIN]
        hi = [np.log(OMEGA_MAX), np.log(OMEGA_MAX), ZETA_MAX]
        x0 = np.clip([np.log(scalar(p["omega_root"])), np.log(scalar(p["omega_tip"])), scalar(p["zeta"])],
                     np.array(lo) + 1e-6, np.array(hi) - 1e-6)
        # a few steps with z held fixed, deliberately: with z profiled out (re-solved for every trial state)
        # the fit does reach a lower in-sample error than the true parameters', but by walking to a sharp
        # resonance (zeta at its bound 0.03, a 1-3-frame root period) whose inverse lets the free z fit noise:
        # simulated dynamics at 0.75x default, seeds 0-2, held-out RMSE 3-12 % *worse* than the rank-1 model's.
        # Running the alternation of these steps and z further (four rounds of both per sweep) gets there too on
        # some recordings: 0.75x seeds 0-24, dynamics named 8 -> 6, seed 21's held-out gain +1.3 % -> -9.1 %
        # (a 100-sweep cap instead of 25 did name dynamics on 3 of the 4 recordings the oracle's pair test
        # separates and the verdict called delay, seeds 61, 66, 79; not measured beyond them). The diagnosis'
        # 25-sweep cap (FULL_ITER) is, in effect, this fit's regularisation
        res = least_squares(lambda q: view.residual_vector(i, self._state(q)), x0, bounds=(lo, hi),
                            diff_step=1e-4, max_nfev=3)
        return self._state(res.x)

    def alternative_starts(self, state):
        """The fitted natural frequencies with each damping ratio of :data:`ZETA_STARTS` that differs from the
        fitted one by more than a factor 1.5. From its grid start the fit can walk to a sharp resonance (zeta at
        its lower bound) that fits the tip rows' noise through z (:mod:`rce_gtsam.model.starts`); a damped
        start leads to the other optimum, and cross-prediction between row sets chooses."""
        p = state["params"]
        zeta = scalar(p["zeta"])
        logs = (np.log(scalar(p["omega_root"])), np.log(scalar(p["omega_tip"])))
        return [self._state((*logs, z)) for z in ZETA_STARTS if abs(np.log(z / zeta)) > np.log(1.5)]

    def score_directions(self, kappa, z, s):
        """Far below resonance the oscillator is 1 - (2 zeta / w_e) d/dt + ((4 zeta^2 - 1) / w_e^2) d2/dt2 + ...;
        with 1 / w_e and 1 / w_e^2 varying along the branch, to first order in root distance the effect moves
        kappa_e z_t along kappa_e s_e dz/dt and kappa_e s_e d2z/dt2 (the parts common to all segments are
        absorbed by z). Two directions (degrees per frame, per frame^2)."""
        dz = np.gradient(np.asarray(z, float))
        ks = kappa[:, None] * s[:, None]
        return np.stack([ks * dz[None, :], ks * np.gradient(dz)[None, :]])

    def describe(self, state):
        p = state["params"]
        return {"period_root_frames": float(2 * np.pi / scalar(p["omega_root"])),
                "period_tip_frames": float(2 * np.pi / scalar(p["omega_tip"]))}

    def evidence(self, ctx) -> dict:
        """Residual ~ kappa_e b_e d2z/dt2 with a tip-ward trend of b_e (t statistic), and the peak of the
        residual-to-signal spectrum ratio inside the band where z has power (a resonance it excites)."""
        from scipy import signal

        R, k, z = ctx.R, ctx.kappa, ctx.z
        E, T = R.shape
        d2z = np.gradient(np.gradient(z))
        acc, acc_se = per_edge_regression(R, k[:, None] * d2z[None, :])
        acc_se = acc_se * math.sqrt(ctx.inflation)
        aslope, at, ar = slope_vs(ctx.s, acc, acc_se)
        Rf = np.where(np.isfinite(R), R, 0.0)
        nper = int(min(256, T))
        f, pr = signal.welch(Rf, nperseg=nper, axis=1)
        _, pz = signal.welch(z, nperseg=nper)
        ratio = pr.mean(axis=0) / np.maximum(pz * np.mean(k * k), 1e-300)
        band = (f > 0) & (pz > 1e-3 * pz.max())
        if band.any():
            j = np.flatnonzero(band)[np.argmax(ratio[band])]
            peak_f, peak_ratio = float(f[j]), float(ratio[j] / max(np.median(ratio[band]), 1e-300))
        else:
            peak_f, peak_ratio = float("nan"), float("nan")
        return {"accel_coef_per_edge_frames2": acc, "accel_slope_frames2": aslope, "accel_slope_t": at,
                "accel_vs_root_distance_r": ar, "residual_to_signal_spectrum_peak_cycles_per_frame": peak_f,
                "residual_to_signal_spectrum_peak_over_median": peak_ratio}

    def longest_period_frames(self, state) -> float:
        """The longest natural period of the fitted state (frames): root's or tip's."""
        d = self.describe(state)
        return max(d["period_root_frames"], d["period_tip_frames"])

    def implausible(self, state, ctx):
        """Every natural period under ``ctx.shortest_period_frames``: an oscillator the video cannot resolve (it
        fits frame-to-frame tracker jitter). A root or tip at the top frequency bound alone is quasi-static,
        a physical limit (:attr:`natural_limits`)."""
        longest = self.longest_period_frames(state)
        if longest < ctx.shortest_period_frames:
            return [f"its longest natural period, {longest:.3g} frames, is under {ctx.shortest_period_frames:g} "
                    f"frames: the video cannot resolve such an oscillation"]
        return []

    def explain(self, summary: dict, statistics: dict) -> str:
        zeta = (summary.get("zeta") or {}).get("value") or float("nan")
        return (f"Fitted natural periods {summary.get('period_root_frames', float('nan')):.1f} frames at the root "
                f"and {summary.get('period_tip_frames', float('nan')):.1f} frames at the tip, damping ratio "
                f"{zeta:.2f}; residual spectrum peaks at "
                f"{statistics.get('residual_to_signal_spectrum_peak_cycles_per_frame', float('nan')):.3f} cycles/frame.")
