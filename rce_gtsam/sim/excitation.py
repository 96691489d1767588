"""The wind excitation z(t) the simulators drive their branches with (deg): band-limited, gusty, seeded.

Its own module so the planar laws (:mod:`.bend_laws`) and the 3-D scene (:mod:`.three_d`) share it without
importing each other.
"""

from __future__ import annotations

import numpy as np
from scipy import signal


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
