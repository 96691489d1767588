"""The wind excitation and the laws of the simulator's in-plane effects (:mod:`rce_gtsam.sim.simulate`).

``make_excitation`` draws the signed wind excitation z[t] (degrees); ``bend_response`` turns kappa and z into the
true bend deviations y[e, t] (degrees) with the switched-on effects (:data:`EFFECTS`, their strengths
:data:`EFFECT_DEFAULTS` and forms :data:`EFFECT_FORMS`). Time unit: the video frame.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal
from scipy.interpolate import make_interp_spline

from .three_d import DEFAULT_SHARE, MEANING as _OOP_MEANING

#: Names of the physical effects the simulator can switch on (and the diagnosis looks for).
EFFECTS: tuple[str, ...] = ("delay", "dynamics", "second_mode", "offset", "nonlinear")

#: Default strength of each effect and what the number means. The defaults are "modest": on clean
#: data each effect's misfit to the best rank-1 model is about 0.2-0.3 of the bending signal's RMS
#: (enforced by tests/test_simulate.py), i.e. visible in the residuals but small next to the signal.
EFFECT_DEFAULTS: dict[str, float] = {
    "delay": 15.0,       # tau_tip: lag of the most distal edge behind z, in frames (0.5 s at 30 fps)
    "dynamics": 1.3,     # tip natural period T_tip in seconds (0.77 Hz); the root edge's period is T_tip / 3
    "second_mode": 0.25, # RMS of the second-mode term mu_e*w_t divided by RMS of kappa_e*z_t
    "offset": 0.3,       # RMS of the offset+creep term c_e + d_e*t/T divided by RMS of kappa_e*z_t
    "nonlinear": 3.0,    # q / y_s: largest linear deflection q (99th pct of |kappa_e z_t|) over saturation y_s
    "out_of_plane": DEFAULT_SHARE,  # share of the wind swinging the branch out of its plane (sim/three_d.py)
}

EFFECT_MEANING: dict[str, str] = {
    "delay": "tau_tip in frames: y_e(t) = kappa_e * z(t - tau_tip * s_e)",
    "dynamics": "tip natural period in seconds: damped 2nd-order oscillator per edge driven by kappa_e * z",
    "second_mode": "RMS(mu_e w_t) / RMS(kappa_e z_t): independent second excitation with its own pattern",
    "offset": "RMS(c_e + d_e t/T) / RMS(kappa_e z_t): constant offset and linear creep per edge",
    "nonlinear": "q / y_s: saturation y_e = y_s tanh(kappa_e z_t / y_s), q = 99th percentile of |kappa_e z_t|",
    "out_of_plane": _OOP_MEANING,
}


#: The form each effect takes in the simulator: the first is the default (the one the diagnosis' candidates are
#: written in); the others are *held-out forms*, physics the candidates do not model exactly, so that the
#: diagnosis can be checked on data it was not shaped on (``benchmarks/bench_diagnose.py --held-out``,
#: ``rce simulate --form``). Never tune the diagnosis on them: they stand in for another simulator and for real
#: plants.
EFFECT_FORMS: dict[str, dict[str, str]] = {
    "delay": {"linear": "lag tau_tip * s_e, linear in root distance",
              "quadratic": "lag tau_tip * s_e^2: a bending wave that slows toward the thinner tip"},
    "dynamics": {"graded": "natural period falling linearly from T_tip at the tip to T_tip/3 at the root; zeta "
                           "uniform in [0.1, 0.3]",
                 "scattered": "each joint's period log-uniform in [T_tip/3, T_tip] whatever its place on the "
                              "branch; zeta uniform in [0.05, 0.5]"},
    "second_mode": {"gusts": "w_t made like z (gusts and a slow sway); pattern a half-cosine along the branch "
                             "plus per-joint variation",
                    "flutter": "w_t a narrow-band flutter at 1.5-2.5 Hz (a leaf or a side shoot); pattern on the "
                               "distal half of the branch only"},
    "offset": {"linear": "c_e + d_e t/T: a constant and a linear creep",
               "relaxation": "c_e + d_e (1 - exp(-t / (T/4))): a creep that relaxes toward a new rest"},
    "nonlinear": {"symmetric": "y_s tanh(u / y_s): joints stiffen in both directions",
                  "one_sided": "only deflections toward the prevailing wind saturate (the branch comes to rest "
                               "against a stop or a neighbour)"},
}


def default_form(effect: str) -> str:
    """The form of ``effect`` the diagnosis' candidates are written in: the first of :data:`EFFECT_FORMS`."""
    return next(iter(EFFECT_FORMS[effect]))


# ----------------------------------------------------------------------------------------------------------
# Excitation
# ----------------------------------------------------------------------------------------------------------

def make_excitation(n_frames: int, fps: float, rng: np.random.Generator, rms_deg: float = 1.5,
                    calm_s: float = 0.5, ramp_s: float = 1.0) -> np.ndarray:
    """A signed wind excitation z[t] in degrees, RMS ``rms_deg``.

    Sum of: gusts (smooth asymmetric bumps, fast rise ~0.3-1 s, slower decay, 80 % in the prevailing
    direction, on average one every 6 s), a slow periodic sway (0.25-0.6 Hz, slowly amplitude-modulated) and
    coloured noise (white noise through a 4th-order Butterworth low-pass at 1 Hz). The first ``calm_s``
    seconds are exactly 0 (the branch is at rest there) and a raised-cosine ramp of ``ramp_s`` seconds
    blends the wind in. Wind content is kept below ~1.5 Hz, as in the real plants' excitation.
    """
    t = np.arange(n_frames) / fps
    dur = n_frames / fps
    z = np.zeros(n_frames)
    n_gusts = max(1, rng.poisson(dur / 6.0))
    for _ in range(n_gusts):
        t0 = rng.uniform(0, dur)
        rise = rng.uniform(0.3, 1.0)
        decay = rng.uniform(0.8, 2.5)
        amp = rng.uniform(0.6, 1.4) * (1 if rng.uniform() < 0.8 else -1)
        dt = t - t0
        bump = np.where(dt < 0, np.exp(-0.5 * (dt / rise) ** 2), np.exp(-0.5 * (dt / decay) ** 2))
        z += amp * bump
    f0 = rng.uniform(0.25, 0.6)
    mod = 1 + 0.5 * np.sin(2 * np.pi * t / rng.uniform(8, 20) + rng.uniform(0, 2 * np.pi))
    z += 0.35 * mod * np.sin(2 * np.pi * f0 * t + rng.uniform(0, 2 * np.pi))
    b, a = signal.butter(4, min(1.0 / (fps / 2), 0.99))
    noise = signal.filtfilt(b, a, rng.standard_normal(n_frames + 200))[100:-100]
    noise /= max(np.std(noise), 1e-12)
    z += 0.3 * noise
    n_calm = min(int(round(calm_s * fps)), n_frames - 1)
    n_ramp = max(1, int(round(ramp_s * fps)))
    t_ramp = np.arange(n_frames) - n_calm
    env = np.where(t_ramp < 0, 0.0, np.where(t_ramp >= n_ramp, 1.0, 0.5 - 0.5 * np.cos(np.pi * t_ramp / n_ramp)))
    z = (z - z[n_calm]) * env
    rms = np.sqrt(np.mean(z ** 2))
    return z * (rms_deg / rms) if rms > 0 else z


# ----------------------------------------------------------------------------------------------------------
# Effects
# ----------------------------------------------------------------------------------------------------------

def delayed(z: np.ndarray, tau: float) -> np.ndarray:
    """z(t - tau) for a fractional delay ``tau`` >= 0 in frames (cubic-spline interpolation; z(t<0) = z(0))."""
    t = np.arange(len(z), dtype=float)
    spline = make_interp_spline(t, z, k=3)
    return spline(np.clip(t - tau, 0.0, None))


def oscillator_response(u: np.ndarray, omega: float, zeta: float) -> np.ndarray:
    """Response of  y'' + 2 zeta omega y' + omega^2 y = omega^2 u  (time unit: frames, omega in rad/frame).

    Discretised exactly for an input that is linear between frames (first-order hold,
    ``scipy.signal.cont2discrete(method="foh")``), zero initial state. Static gain 1.
    """
    A = np.array([[0.0, 1.0], [-omega ** 2, -2 * zeta * omega]])
    B = np.array([[0.0], [omega ** 2]])
    C = np.array([[1.0, 0.0]])
    D = np.array([[0.0]])
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), dt=1.0, method="foh")
    _, y, _ = signal.dlsim((Ad, Bd, Cd, Dd, 1.0), u.reshape(-1, 1))
    return y[:, 0]


def bend_response(kappa: np.ndarray, s: np.ndarray, z: np.ndarray, effects: tuple[str, ...],
                  strength: dict[str, float], fps: float, rng: np.random.Generator,
                  forms: dict[str, str] | None = None) -> tuple[np.ndarray, dict]:
    """True bend responses y[e, t] in degrees and the parameters of every active effect.

    ``forms``: per effect, one of :data:`EFFECT_FORMS` (default: the first, described below; the held-out forms
    change the law as :data:`EFFECT_FORMS` says, at the same strength and in the same units).

    Parameters: ``kappa`` (E,) compliance; ``s`` (E,) child's root distance normalised to [0, 1];
    ``z`` (F,) excitation in degrees; ``strength`` per effect (see :data:`EFFECT_MEANING`).

    Baseline: ``y[e,t] = kappa_e z_t``. Effects, applied in this order when several are on:

    1. ``delay``:  the load reaches distal segments later:  ``u_e(t) = kappa_e z(t - tau_e)``,
       ``tau_e = tau_tip * s_e`` frames (fractional, cubic interpolation).  Params: ``tau_frames`` per edge.
    2. ``dynamics``: each edge is a damped 2nd-order oscillator driven by its quasi-static load u_e:
       ``y'' + 2 zeta_e omega_e y' + omega_e^2 y = omega_e^2 u_e`` (frames; omega_e in rad/frame). The natural
       period falls linearly from T_tip (strength, seconds) at the tip to T_tip/3 at the root; zeta_e is
       uniform in [0.1, 0.3] (seeded). Params: ``omega_rad_per_frame``, ``freq_hz``, ``zeta`` per edge.
    3. ``nonlinear``: large-deflection stiffening of each joint: ``y_e = y_s tanh(u_e / y_s)`` with a
       saturation angle ``y_s = q / strength`` degrees, q = 99th percentile of |kappa_e z_t| (the larger
       gusts). Note: a saturation of the *shared* z (kappa_e z_s tanh(z/z_s)) would still be exactly rank 1
       and so invisible to any residual test; saturating each joint's own deflection is not rank 1, because
       compliant joints saturate more. Params: ``y_s_deg``.
    4. ``second_mode``: an independent second excitation w_t (crosswind / out-of-plane swing; generated
       like z with its own seed, RMS 1 degree) with its own spatial pattern mu_e (a half-cosine along the
       branch plus independent per-edge variation: not proportional to kappa):
       ``y_e += mu_e w_t``, scaled so RMS(mu w) = strength * RMS(kappa z). Params: ``mu``, ``w``.
    5. ``offset``: the true rest pose is not the first frame's pose and creeps (gravity sag, relaxation):
       ``y_e += c_e + d_e t / T`` with T = n_frames, c_e and d_e independent normals of equal spread, scaled
       so RMS(c + d t/T) = strength * RMS(kappa z). Params: ``c_deg``, ``d_deg`` per edge.
    """
    E, F = len(kappa), len(z)
    params: dict[str, dict] = {}
    base = np.outer(kappa, z)
    u = base
    form = {e: (forms or {}).get(e, default_form(e)) for e in EFFECTS}
    for e, f in form.items():
        if f not in EFFECT_FORMS[e]:
            raise ValueError(f"form {f!r} of {e}: expected one of {', '.join(EFFECT_FORMS[e])}")
    if "delay" in effects:
        tau_tip = strength["delay"]
        tau = tau_tip * (s ** 2 if form["delay"] == "quadratic" else s)
        u = np.stack([kappa[e] * delayed(z, tau[e]) for e in range(E)])
        params["delay"] = {"tau_tip_frames": tau_tip, "tau_frames": tau.tolist()}
    if "dynamics" in effects:
        T_tip = strength["dynamics"]
        if form["dynamics"] == "scattered":
            period_s = T_tip / 3 * np.exp(np.log(3.0) * rng.uniform(0, 1, E))
            zeta = rng.uniform(0.05, 0.5, E)
        else:
            period_s = T_tip / 3 + (T_tip - T_tip / 3) * s
            zeta = rng.uniform(0.1, 0.3, E)
        if T_tip > 0:
            omega = 2 * np.pi / (period_s * fps)
            u = np.stack([oscillator_response(u[e], omega[e], zeta[e]) for e in range(E)])
        else:
            omega = np.full(E, np.inf)
        params["dynamics"] = {"tip_period_s": T_tip, "omega_rad_per_frame": omega.tolist(),
                              "freq_hz": (1 / period_s if T_tip > 0 else np.full(E, np.inf)).tolist(),
                              "zeta": zeta.tolist()}
    if "nonlinear" in effects:
        ratio = strength["nonlinear"]
        q = float(np.quantile(np.abs(base), 0.99))
        if ratio > 0 and q > 0:
            y_s = q / ratio
            # one-sided: only deflections toward the prevailing wind (the sign of z's mean) saturate
            side = np.sign(np.mean(base)) or 1.0
            u = (np.where(side * u > 0, y_s * np.tanh(u / y_s), u) if form["nonlinear"] == "one_sided"
                 else y_s * np.tanh(u / y_s))
        else:
            y_s = math.inf
        params["nonlinear"] = {"q_deg": q, "y_s_deg": y_s, "ratio": ratio}
    y = u
    ref_rms = float(np.sqrt(np.mean(base ** 2)))
    if "second_mode" in effects:
        if form["second_mode"] == "flutter":
            f0 = rng.uniform(1.5, 2.5)
            w = signal.sosfiltfilt(signal.butter(2, [0.8 * f0, 1.25 * f0], "bandpass", fs=fps, output="sos"),
                                   rng.standard_normal(F))
            w /= max(float(np.sqrt(np.mean(w ** 2))), 1e-12)
            mu = np.where(s > 0.5, 1.0 + 0.5 * rng.standard_normal(E), 0.0)
        else:
            w = make_excitation(F, fps, rng, rms_deg=1.0)
            mu = np.cos(np.pi * s) + 0.5 * rng.standard_normal(E)
        term = np.outer(mu, w)
        r = np.sqrt(np.mean(term ** 2))
        scale = strength["second_mode"] * ref_rms / r if r > 0 else 0.0
        mu = mu * scale
        y = y + np.outer(mu, w)
        params["second_mode"] = {"ratio": strength["second_mode"], "mu": mu.tolist(), "w": w.tolist()}
    if "offset" in effects:
        c = rng.standard_normal(E)
        d = rng.standard_normal(E)
        tt = np.arange(F) / F
        if form["offset"] == "relaxation":
            tt = 1.0 - np.exp(-np.arange(F) / (F / 4))
        term = c[:, None] + d[:, None] * tt[None, :]
        r = np.sqrt(np.mean(term ** 2))
        scale = strength["offset"] * ref_rms / r if r > 0 else 0.0
        c, d = c * scale, d * scale
        y = y + c[:, None] + d[:, None] * tt[None, :]
        params["offset"] = {"ratio": strength["offset"], "c_deg": c.tolist(), "d_deg": d.tolist()}
    for e in params:
        params[e]["form"] = form[e]
    return y, params
