"""Is a candidate's fit physically plausible on this recording? An implausible fit is never named, whatever its
tests say.

A test statistic only says that the extended model predicts held-out frames better than the rank-1 model; it
does not say that the extension describes the branch. A tracker's errors are deterministic functions of the
motion (compression at large deflection, lag under fast motion, blur), and a flexible term can absorb them with
parameters no branch has. Measured on the user's path (``benchmarks/bench_user_path.py``: our tracker on
rendered video), effect-free recordings were named

* ``nonlinear`` with a saturation angle of 24-74 deg where the largest deflection was 6-9 deg: the curve is
  then a straight line over every deflection seen, and the "gain" is a small even distortion of the tracks;
* ``dynamics`` with a natural period of 1.0 frame and damping 0.03, both at the edge of their range: an
  oscillator at the frame rate fits frame-to-frame tracker jitter, not a branch.

A fit is *implausible* when any of these holds (the reason is recorded in the candidate's
``extra["implausible"]`` and said in the explanation):

* a shared parameter sits at a bound of its range (the optimum lies outside the form the effect describes),
  except a bound the effect declares a physical limit (:attr:`~rce_gtsam.effects.Effect.natural_limits`:
  a natural frequency at its top is a quasi-static joint, not an edge case);
* whatever the effect itself declares in :meth:`~rce_gtsam.effects.Effect.implausible`, against the
  recording's own scales in :class:`PlausibilityContext`: a saturation beyond twice the largest deflection
  seen, a natural period under :data:`SHORTEST_PERIOD_FRAMES`, a lag longer than the excitation's
  correlation time or shorter than :data:`SHORTEST_LAG_FRAMES`.

These are statements about physics and sampling, not thresholds fitted to a simulator: each is a scale the
recording itself sets (its deflections, its frame rate, its excitation's memory).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .result import TestResult

#: A natural period shorter than this many frames (a frequency above a quarter of the frame rate, half the
#: Nyquist frequency) is not resolved by the video: an oscillator there fits frame-to-frame tracker jitter.
SHORTEST_PERIOD_FRAMES = 4.0
#: A tip lag shorter than this many frames (one frame interval) is what the camera's own timing puts between root
#: and tip: a rolling shutter (the D435i's colour sensor, like most) reads the image's rows out over up to one frame
#: interval, so a branch spanning the image is sampled up to a frame later at one end than at the other. Measured on
#: the user's path (record ``user_path``): the one effect-free render named delay had a tip lag of -0.96 frames; the
#: hidden lags found were 8-17 frames.
SHORTEST_LAG_FRAMES = 1.0
#: A saturation angle beyond this multiple of the largest deflection seen (99th percentile of |kappa z|) bends
#: the largest deflection by less than (1/2)^2 / 3 = 8 %: a curve never reached is not observed.
SATURATION_REACH = 2.0
#: How close (share of the range, in log units for a range of positive numbers) a parameter must be to a
#: bound to count as sitting on it.
AT_BOUND = 0.01


@dataclass(frozen=True)
class PlausibilityContext:
    """The recording's own scales a fit is judged against.

    q99_deflection_deg: 99th percentile of the rank-1 model's |kappa_e z_t| (deg), the largest deflection
    seen; correlation_time_frames: the excitation's memory (frames; the first lag where the autocorrelation of z
    is no longer positive), the longest lag the record can tell from another signal;
    n_frames: frames in the record; shortest_period_frames, shortest_lag_frames, saturation_reach: the limits an
    effect checks against (:data:`SHORTEST_PERIOD_FRAMES`, :data:`SHORTEST_LAG_FRAMES`, :data:`SATURATION_REACH`),
    carried here so that effects need not import the diagnosis."""

    q99_deflection_deg: float
    correlation_time_frames: float
    n_frames: int
    shortest_period_frames: float = SHORTEST_PERIOD_FRAMES
    shortest_lag_frames: float = SHORTEST_LAG_FRAMES
    saturation_reach: float = SATURATION_REACH

    @classmethod
    def from_fit(cls, fit) -> "PlausibilityContext":
        """The scales of a rank-1 fit (:class:`~rce_gtsam.model.ModelFit`)."""
        P = np.abs(np.asarray(fit.kappa)[:, None] * np.asarray(fit.z)[None, :])
        q99 = float(np.nanquantile(P, 0.99)) if np.isfinite(P).any() else float("nan")
        return cls(q99_deflection_deg=q99, correlation_time_frames=correlation_time(fit.z),
                   n_frames=int(len(fit.z)))


def correlation_time(z) -> float:
    """The excitation's memory in frames: the first lag at which its autocorrelation is no longer positive (NaN
    frames taken as the mean). Beyond it the lagged excitation is another signal, not the same one later. A
    series shorter than 3 frames gives NaN; one whose autocorrelation never falls to zero gives its length."""
    z = np.asarray(z, float)
    if z.size < 3:
        return float("nan")
    z = np.where(np.isfinite(z), z, np.nanmean(z)) - np.nanmean(z)
    n = z.size
    f = np.fft.rfft(z, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:n]
    if ac[0] <= 0:
        return float("nan")
    neg = np.flatnonzero(ac <= 0)
    return float(neg[0]) if neg.size else float(n)


def at_bound(value: float, lower: float, upper: float) -> str | None:
    """"lower" / "upper" where ``value`` lies within :data:`AT_BOUND` of that finite bound (in log units when
    both bounds are positive), else None."""
    if not math.isfinite(value):
        return None
    if lower > 0 and math.isfinite(upper) and value > 0:
        lo, hi, v = math.log(lower), math.log(upper), math.log(value)
    else:
        lo, hi, v = lower, upper, value
    # a range open on one side has no scale to measure closeness by: only a value on the bound itself counts
    span = hi - lo if math.isfinite(hi - lo) else 0.0
    tol = AT_BOUND * span if span > 0 else 1e-9
    if math.isfinite(lo) and v <= lo + tol:
        return "lower"
    if math.isfinite(hi) and v >= hi - tol:
        return "upper"
    return None


def implausibility(effect, state: dict, n_edges: int, ctx: PlausibilityContext) -> tuple[str, ...]:
    """Why a fitted effect term (``effect`` with its fitted ``state``) is not plausible physics on this recording:
    one sentence per reason, empty where it is plausible."""
    reasons = []
    limits = getattr(effect, "natural_limits", {})
    for p in effect.parameters(n_edges):
        if p.per_edge or p.name not in state.get("params", {}):
            continue
        value = float(np.ravel(state["params"][p.name])[0])
        side = at_bound(value, p.lower, p.upper)
        if side is not None and side not in limits.get(p.name, ()):
            bound = p.lower if side == "lower" else p.upper
            reasons.append(f"{p.name} = {value:.3g} {p.unit} sits at the {side} bound of its range ({bound:.3g}): "
                           f"the best fit lies outside the form this effect describes")
    reasons.extend(effect.implausible(state, ctx))
    return tuple(reasons)


NULL = ("none: each reason is a scale the recording itself sets (a parameter's range, the frame rate, the largest "
        "deflection seen, the excitation's memory); fires on any reason")
CALIBRATION = ("benchmarks/bench_user_path.py (effect-free rendered video named nonlinear or dynamics with such "
               "fits before)")


def implausibility_result(reasons: tuple) -> TestResult:
    """:func:`implausibility`'s reasons as a result: the statistic is their number, and it fires on any."""
    return TestResult("implausibility", float(len(reasons)), None, 0.0, NULL, CALIBRATION)
