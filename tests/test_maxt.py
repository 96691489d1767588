"""The sign-flip max-T test of candidates' held-out gains (rce_gtsam.diagnosis.maxt)."""

import numpy as np
from scipy import stats

from rce_gtsam.diagnosis.maxt import sign_flip_max_t


def _folds(rng, gain, n_cand=5, K=8, shared=0.02, own=0.01):
    ref = np.exp(rng.normal(0, 0.3, K))  # calm and gusty folds: the spread the fold t has to live with
    common = rng.normal(0, shared, K)
    return ref, [ref * np.exp(-(g + common + rng.normal(0, own, K))) for g in gain]


def test_family_wise_false_alarms_at_most_alpha_on_symmetric_null():
    rng = np.random.default_rng(0)
    hits = sum((sign_flip_max_t(*_folds(rng, [0.0] * 5)).p_adjusted <= 0.05).any() for _ in range(400))
    assert hits / 400 <= 0.05 + 2 * np.sqrt(0.05 * 0.95 / 400)


def test_correlated_candidates_get_a_lower_threshold_than_bonferroni():
    """Five candidates that move together (delay and dynamics fit the same lag) are nearly one test: the max-T
    critical t is below the Bonferroni t quantile, and identical candidates give exactly the one-test value."""
    rng = np.random.default_rng(1)
    ref, c = _folds(rng, [0.0] * 5, shared=0.02, own=0.001)
    many = sign_flip_max_t(ref, c)
    one = sign_flip_max_t(ref, c[:1])
    same = sign_flip_max_t(ref, [c[0]] * 5)
    assert same.critical_t == one.critical_t
    assert many.critical_t < stats.t.ppf(1 - 0.05 / 5, 7)
    assert many.n_flips == 2 ** 8


def test_a_real_gain_is_significant_and_only_it():
    rng = np.random.default_rng(2)
    ref, c = _folds(rng, [0.06, -0.01, -0.01, -0.02, 0.0], shared=0.0, own=0.01)
    r = sign_flip_max_t(ref, c)
    assert r.p_adjusted[0] <= 0.05 and (r.p_adjusted[1:] > 0.05).all()
