"""Camera nuisances for :mod:`rce_gtsam.sim.render`: what makes a real outdoor clip harder than a clean render.

A :class:`RenderConfig` (frozen, data only) says how a simulation is filmed. Its defaults reproduce the
clean render exactly (bit-identical frames and video); each nuisance is switched on by a non-zero field:

* **motion blur** (``exposure``): the shutter is open for ``exposure`` x the frame period, centred on the
  frame's instant; the frame is the mean of sub-frame renders spread evenly over that interval (node
  positions interpolated linearly between the neighbouring frames, leaf flutter at the sub-frame time).
  The number of sub-frames adapts to the motion: the fastest node moves at most ``blur_step_px`` between
  two of them (at most ``max_subframes``). 0.5 is the usual 180-degree shutter of video cameras.
* **illumination drift** (``gain_sd``, ``offset_sd``, ``light_time_s``): a global gain exp(gain_sd * a(t))
  and offset offset_sd * b(t) (grey levels), a(t), b(t) smooth unit-variance random processes with
  correlation time ``light_time_s`` seconds -- clouds and the camera's auto-exposure. gain_sd 0.12 keeps
  95 % of frames within about +-25 % of the mean brightness.
* **moving soft shadow** (``shadow_depth``): a straight penumbra ``shadow_width_px`` wide (10-90 %) in a
  random direction that drifts back and forth over the branch (RMS speed ``shadow_speed_px_s``, RMS
  excursion about 2 s of that speed, so ~40 px at the default); the shadowed side
  is darker by the fraction ``shadow_depth``. Applied as a multiplicative field, so inside one tracking
  patch it is a brightness gradient.
* **camera shake** (``shake_px``, ``shake_time_s``): a whole-image translation, a smooth random process of
  RMS ``shake_px`` per axis and correlation time ``shake_time_s``, shifted so that frame 0 is not moved
  (frame-0 annotations stay valid). A tracker must report the node where it is *in the image*:
  :func:`image_xy` = ``sim.true_xy`` + :func:`camera_shift`. The background is translated by Lanczos
  interpolation; the camera's own motion during the exposure (< 0.1 px at the preset) is not blurred.
* **compression** (``crf``): x264 constant rate factor; 16 keeps the bark texture crisp, 28-30 is what a
  phone or action camera's bit rate gives.

Every random process takes its own seed derived from the simulation seed (``SeedSequence([seed, tag])``),
so switching one nuisance on leaves the others and the scene unchanged. Units: pixels, grey levels
(0-255), seconds; the processes are sampled per frame at the simulation's fps.

:data:`REALISM` names the presets (``clean``, ``outdoor``) that ``rce simulate --realism`` offers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from scipy.ndimage import gaussian_filter1d

_TAG_SHAKE, _TAG_LIGHT, _TAG_SHADOW = 0x5A4E, 0x11647, 0x5AD0


@dataclass(frozen=True)
class RenderConfig:
    """How a simulation is filmed (see the module docstring). Defaults = the clean render.

    crf: x264 constant rate factor of :func:`~rce_gtsam.sim.render.render_video`.
    sensor_noise: per-pixel Gaussian noise, grey levels RMS, independent per frame.
    exposure: shutter-open time as a fraction of the frame period (0 = instantaneous, no motion blur).
    blur_step_px: largest node displacement (pixels) between two sub-frames of the blur.
    max_subframes: upper bound on the number of sub-frames per frame.
    gain_sd: standard deviation of the log global gain (0 = constant lighting).
    offset_sd: standard deviation of the global offset, grey levels.
    light_time_s: correlation time (seconds) of the gain and offset drift.
    shadow_depth: darkening on the shadowed side of the moving penumbra (fraction, 0 = no shadow).
    shadow_width_px: width of the penumbra (pixels, 10-90 % of the darkening).
    shadow_speed_px_s: RMS speed of the penumbra across the image (pixels per second).
    shake_px: RMS camera translation per axis (pixels, 0 = tripod perfectly still).
    shake_time_s: correlation time of the camera translation (seconds).
    """

    crf: int = 16
    sensor_noise: float = 1.0
    exposure: float = 0.0
    blur_step_px: float = 0.5
    max_subframes: int = 16
    gain_sd: float = 0.0
    offset_sd: float = 0.0
    light_time_s: float = 1.5
    shadow_depth: float = 0.0
    shadow_width_px: float = 60.0
    shadow_speed_px_s: float = 15.0
    shake_px: float = 0.0
    shake_time_s: float = 0.15

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"RenderConfig.{f.name} must be a finite number >= 0, got {v!r}")
        if self.exposure > 1:
            raise ValueError(f"RenderConfig.exposure is a fraction of the frame period (0..1), got {self.exposure}")
        if not 0 <= self.crf <= 51:
            raise ValueError(f"RenderConfig.crf must be in 0..51, got {self.crf}")
        if self.shadow_depth >= 1:
            raise ValueError(f"RenderConfig.shadow_depth must be < 1, got {self.shadow_depth}")
        if self.max_subframes < 1 or self.blur_step_px <= 0 or self.shadow_width_px <= 0:
            raise ValueError("RenderConfig: max_subframes >= 1, blur_step_px > 0 and shadow_width_px > 0 required")

    @property
    def lighting(self) -> bool:
        """Whether any illumination nuisance (gain, offset, shadow) is on."""
        return self.gain_sd > 0 or self.offset_sd > 0 or self.shadow_depth > 0


#: Named presets: ``clean`` = the default render; ``outdoor`` = a tripod clip outdoors on a breezy, partly
#: cloudy day (180-degree shutter, drifting light and a passing soft shadow, ~1 px tripod shake, phone-like
#: compression).
REALISM: dict[str, RenderConfig] = {
    "clean": RenderConfig(),
    "outdoor": RenderConfig(crf=28, exposure=0.5, gain_sd=0.12, offset_sd=4.0, shadow_depth=0.3, shake_px=1.0),
}


def smooth_process(rng: np.random.Generator, n: int, corr_frames: float, dims: int = 1) -> np.ndarray:
    """(n, dims) smooth Gaussian random process of unit variance: white noise through a Gaussian kernel of
    standard deviation ``corr_frames`` frames (padded so the ends are as smooth as the middle)."""
    s = max(float(corr_frames), 0.5)
    pad = int(math.ceil(4 * s))
    w = rng.standard_normal((n + 2 * pad, dims))
    x = gaussian_filter1d(w, s, axis=0, mode="nearest")[pad:pad + n]
    # variance of unit white noise through a unit-sum Gaussian kernel of std s: 1 / (2 sqrt(pi) s)
    return x * math.sqrt(2 * math.sqrt(math.pi) * s)


def _rng(seed: int, tag: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), tag]))


def camera_shift(sim, config: RenderConfig) -> np.ndarray:
    """(F, 2) camera-induced image translation per frame (pixels, x and y); zero at frame 0 and when
    ``config.shake_px`` is 0. Seeded by the simulation seed."""
    F = sim.true_xy.shape[1]
    if config.shake_px <= 0:
        return np.zeros((F, 2))
    x = smooth_process(_rng(sim.config.seed, _TAG_SHAKE), F, config.shake_time_s * sim.config.fps, dims=2)
    return config.shake_px * (x - x[0])


def image_xy(sim, config: RenderConfig) -> np.ndarray:
    """(N, F, 2) node positions in the rendered image (pixels): ``sim.true_xy`` plus the camera shift.
    This is the ground truth a tracker is measured against."""
    return sim.true_xy + camera_shift(sim, config)[None]


def illumination(sim, config: RenderConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame global gain (F,) (dimensionless, 1 = unchanged) and offset (F,) (grey levels)."""
    F = sim.true_xy.shape[1]
    if config.gain_sd <= 0 and config.offset_sd <= 0:
        return np.ones(F), np.zeros(F)
    ab = smooth_process(_rng(sim.config.seed, _TAG_LIGHT), F, config.light_time_s * sim.config.fps, dims=2)
    return np.exp(config.gain_sd * ab[:, 0]), config.offset_sd * ab[:, 1]


class ShadowField:
    """The moving soft shadow: :meth:`__call__` gives the (H, W) multiplicative brightness of frame f."""

    def __init__(self, sim, config: RenderConfig):
        w, h = sim.config.image_size
        F = sim.true_xy.shape[1]
        rng = _rng(sim.config.seed, _TAG_SHADOW)
        ang = float(rng.uniform(0, 2 * math.pi))
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        c, s = math.cos(ang), math.sin(ang)
        # the penumbra wanders about the branch (its frame-0 centroid, give or take 40 px), so it sweeps over it
        mid = sim.true_xy[:, 0].mean(axis=0)
        self.dist = (xx - mid[0]) * c + (yy - mid[1]) * s - float(rng.uniform(-40, 40))  # along the normal, px
        # penumbra position: a smooth process with RMS speed shadow_speed_px_s (derivative of a Gaussian-
        # filtered process of std 1 and kernel std s frames has std 1 / (sqrt(2) s) per frame)
        s_frames = 2.0 * sim.config.fps
        amp = config.shadow_speed_px_s / sim.config.fps * math.sqrt(2) * s_frames
        self.centre = amp * smooth_process(rng, F, s_frames)[:, 0]
        self.depth = float(config.shadow_depth)
        # tanh(x / k) goes from 10 % to 90 % over 2 k atanh(0.8) = 2.197 k
        self.k = float(config.shadow_width_px) / 2.197

    def __call__(self, f: int) -> np.ndarray:
        edge = 0.5 * (1.0 + np.tanh((self.dist - np.float32(self.centre[f])) / np.float32(self.k)))
        return (1.0 - np.float32(self.depth) * edge).astype(np.float32)
