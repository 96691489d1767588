"""The ideal oracle of a simulated effect: does the data contain a *known* extra signature? The ceiling any
diagnosis of that effect can reach, used by ``benchmarks/beam_ideal_oracle.py``.

The oracle of :mod:`rce_gtsam.diagnosis.oracle` runs the verdict's own tests with the true form and shared
parameters; for an effect with nothing shared to know (a second excitation) it is the candidate itself, so it
measures the verdict's test, not the data. This one knows the whole extra signal: ``signature`` (E, T, deg), the
part of the noise-free response no rank-1 model explains (:func:`rce_gtsam.diagnosis.oracle.true_signature`), and
asks only whether the rank-1 residual ``R`` (E, T, deg) moves along it:

* statistic: the generalised-least-squares projection of R on the signature, sum_t S_t' C^-1 R_t /
  sqrt(sum_t S_t' C^-1 S_t), C the residual noise's correlation between rows (from frame-to-frame
  differences, :func:`rce_gtsam.diagnosis.statistics.noise_correlation`: bends that share a tracked node
  carry noise correlated at about -0.6, which GLS discounts);
* null: the same statistic on phase-randomised surrogates of R
  (:func:`rce_gtsam.model.surrogates.phase_randomised_residuals`: every row's autocorrelation and every pair's
  cross-spectrum kept, only *when* the noise happens is new), one-sided (the signature's sign is known),
  p = (1 + #{surrogate >= observed}) / (1 + n). Where R does contain the signature its surrogates carry the
  signature's power too, which widens the null: the test is conservative, not liberal.

It is no diagnosis (it needs the truth), only the ceiling: where it passes and the diagnosis does not, the
gap is the diagnosis' test, not the data.

Units: degrees (R, signature); the statistic in units of the projection's noise-free scale (deg), p unitless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .score_test import scores_with_null
from .statistics import noise_correlation

#: surrogates of the null by default: p resolves 1/2000, well below the verdict's full-data level (0.005)
N_SURROGATES = 1999


@dataclass(frozen=True)
class SignatureTest:
    """The ideal oracle's result: ``statistic`` (GLS projection of the residual on the known signature, deg),
    ``p`` (one-sided, phase-surrogate null), ``n_surrogates``, ``null_sd`` (the surrogates' SD of the statistic,
    deg) and ``z`` (statistic / null_sd: how many null SDs the data stand along the signature). ``z`` is only a
    description: the null of a slow signature is a sum of few cosines, lighter-tailed than a Gaussian (a
    synthetic case: z 2.5 beyond all 999 surrogates), so ``p`` is what to read."""

    statistic: float
    p: float
    n_surrogates: int
    null_sd: float

    @property
    def z(self) -> float:
        return float(self.statistic / self.null_sd) if self.null_sd > 0 else float("nan")

    def passes(self, level: float) -> bool:
        return bool(self.p <= level)


def signature_test(R: np.ndarray, signature: np.ndarray, seed: int = 0,
                   n_surrogates: int = N_SURROGATES) -> SignatureTest:
    """Whether the residual ``R`` (E, T, deg; NaN = missing) contains the known ``signature`` (E, T, deg): the
    module's GLS projection against phase surrogates of R. ``seed`` seeds the surrogates' phases."""
    R = np.asarray(R, float)
    S = np.asarray(signature, float)
    if R.shape != S.shape:
        raise ValueError(f"signature_test: residual {R.shape} and signature {S.shape} differ in shape")
    if not np.all(np.isfinite(S)):
        raise ValueError("signature_test: the signature has non-finite entries")
    observed = np.isfinite(R)
    Pinv = np.linalg.inv(noise_correlation(R))
    S = S - S.mean(axis=1, keepdims=True)
    D = Pinv @ S  # (E, T) the whitened direction: stat = <D, R>
    norm = float(np.sqrt(max(np.sum(D * np.where(observed, S, 0.0)), 1e-300)))
    score, null_scores = scores_with_null(R, D[None], n_surrogates, seed, robust=False, centre=True)
    stat, null = float(score[0]) / norm, null_scores[:, 0] / norm
    p = float((1 + np.sum(null >= stat)) / (1 + n_surrogates))
    return SignatureTest(statistic=stat, p=p, n_surrogates=int(n_surrogates), null_sd=float(np.std(null)))
