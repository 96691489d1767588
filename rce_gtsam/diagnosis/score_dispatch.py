"""Which full-data score test an effect gets, and how its result is recorded.

An effect names its version in :attr:`~rce_gtsam.effects.Effect.score_excitation`; :func:`effect_score_test` runs
it: ``"own_whitened"`` (:func:`~rce_gtsam.diagnosis.whitened_score_test.whitened_score_test`, the delay),
``"other_rows"`` (:func:`~rce_gtsam.diagnosis.score_test.cross_fitted_score_test`, dynamics and resonances) or
``"between_rows"`` (:func:`~rce_gtsam.diagnosis.score_test.shared_time_course_test`, the second excitation). The
tests themselves, their nulls and their calibration are in those modules.
"""

from __future__ import annotations

import numpy as np

from . import whitened_score_test as whitened
from .result import TestResult
from .score_test import ScoreTest, cross_fitted_score_test, shared_time_course_test

#: the versions an effect may name
VERSIONS = ("own_whitened", "other_rows", "between_rows")


def effect_score_test(excitation: str, model, fit, Y, W, s, fits, halves, directions,
                      seed: int = 0) -> ScoreTest | None:
    """The full-data score test an effect asks for (its ``score_excitation``, one of :data:`VERSIONS`). ``fit``:
    the baseline ``model`` on all rows of Y (E, T, degrees; weights W, root distances s); ``fits``: it on each
    node-disjoint row set of ``halves``; ``directions(rows, kappa, z, s)``: the directions for those rows of Y
    (all of them, or one set's), from that kappa and excitation, as :func:`cross_fitted_score_test` takes them.
    ``model``, ``Y``, ``W``, ``s`` are kept for the callers' one signature (no version refits)."""
    if excitation == "own_whitened":
        every = np.arange(len(fit.kappa))
        return whitened.whitened_score_test(fit, lambda kappa, z, s_: directions(every, kappa, z, s_), seed=seed)
    if excitation == "other_rows":
        return cross_fitted_score_test(halves, fits, lambda i, kappa, z, s_: directions(halves[i], kappa, z, s_),
                                       seed=seed)
    if excitation == "between_rows":
        return shared_time_course_test(fit, halves, seed=seed)
    raise ValueError(f"score_excitation {excitation!r}: expected one of {', '.join(VERSIONS)}")


#: how each version's null is calibrated (by ``score_excitation``)
SCORE_NULLS = {
    "own_whitened": whitened.NULL,
    "other_rows": ("multivariate phase surrogates of both node-disjoint row sets' residuals, the directions from "
                   "the other set's excitation held fixed (2000)"),
    "between_rows": ("multivariate phase surrogates of one node-disjoint row set's residuals against the other's, "
                     "held fixed (2000)"),
}
SCORE_CALIBRATION = ("benchmarks/bench_diagnose.py: 40 effect-free pipeline seeds (dynamics 2/40 below 0.01, shared "
                     "course 0/40 at 0.005); the delay's: benchmarks/bench_delay_test.py (effect-free user path "
                     "1/120, artifact families 0/440, beam 0/40 at 0.005)")


def score_result(test: ScoreTest, excitation: str, threshold_p: float, name: str = "score") -> TestResult:
    """A full-data score test's result (``excitation``: its version) read at ``threshold_p``."""
    return TestResult(name, float(test.q), float(test.p), float(threshold_p),
                      SCORE_NULLS.get(excitation, "phase surrogates of the residuals"), SCORE_CALIBRATION)
