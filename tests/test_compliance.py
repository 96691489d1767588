"""Rank-1 ALS and moving-block bootstrap."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rce_gtsam.model.compliance import fit_rank1, fit_rank1_batch
from rce_gtsam.model.uncertainty import block_bootstrap_indices, bootstrap_kappa
from rce_gtsam.presets import ComplianceConfig

PAPER = ComplianceConfig()
NO_SHRINK = ComplianceConfig(prior_strength=0.0, n_iter=500, tol=1e-10)


def rank1(seed, E=8, T=300, signed=False):
    rng = np.random.default_rng(seed)
    k = np.exp(rng.normal(0, 0.5, E))
    k /= np.exp(np.log(k).mean())
    z = rng.gamma(2.0, 1.0, T) if not signed else rng.normal(0, 2.0, T)
    return k, z, k[:, None] * z[None, :]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), signed=st.booleans())
def test_exact_rank1_data_is_recovered(seed, signed):
    k, z, Y = rank1(seed, signed=signed)
    cfg = ComplianceConfig(response="signed" if signed else "abs", prior_strength=0.0, n_iter=500, tol=1e-12)
    fit = fit_rank1(Y, cfg)
    assert fit.converged
    np.testing.assert_allclose(fit.kappa, k, rtol=1e-6)
    np.testing.assert_allclose(fit.predict(), Y, atol=1e-6 * np.abs(Y).max())


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), frac_missing=st.floats(0.0, 0.4))
def test_geometric_mean_is_one_and_missing_entries_are_ignored(seed, frac_missing):
    k, z, Y = rank1(seed)
    rng = np.random.default_rng(seed + 1)
    Y = Y + rng.normal(0, 0.05, Y.shape)
    Y[rng.random(Y.shape) < frac_missing] = np.nan
    fit = fit_rank1(Y, PAPER)
    assert np.exp(np.log(fit.kappa).mean()) == pytest.approx(1.0, abs=1e-9)
    assert np.all(fit.z >= 0) and np.all(np.isfinite(fit.z))


def test_shrinkage_pulls_sparse_edges_toward_one():
    k, z, Y = rank1(3, E=6, T=400)
    Y[0, 5:] = np.nan  # edge 0 keeps 5 frames only
    shrunk = fit_rank1(Y, ComplianceConfig(prior_strength=12.0))
    free = fit_rank1(Y, NO_SHRINK)
    assert abs(np.log(shrunk.kappa[0])) < abs(np.log(free.kappa[0]))


def test_batch_equals_single_fits():
    rng = np.random.default_rng(0)
    Ys = np.stack([rank1(s)[2] + rng.normal(0, 0.3, (8, 300)) for s in range(4)])
    kb = fit_rank1_batch(Ys, PAPER)[0]
    for b in range(4):
        np.testing.assert_allclose(kb[b], fit_rank1(Ys[b], PAPER).kappa, rtol=1e-12)


def test_signed_response_reports_direction():
    k, z, Y = rank1(5, signed=True)
    Y[2] *= -1
    fit = fit_rank1(Y, ComplianceConfig(response="signed", prior_strength=0.0, n_iter=300, tol=1e-12))
    assert fit.direction[2] == -fit.direction[0]
    np.testing.assert_allclose(fit.kappa, k, rtol=1e-6)


def test_weights_downweight_noisy_entries():
    k, z, Y = rank1(7)
    rng = np.random.default_rng(1)
    noise = np.ones_like(Y) * 0.01
    noise[:, ::2] = 3.0  # every other frame is very noisy
    Yn = Y + rng.normal(0, 1, Y.shape) * noise
    err_w = np.abs(np.log(fit_rank1(np.abs(Yn), NO_SHRINK, weights=1 / noise**2).kappa / k)).max()
    err_u = np.abs(np.log(fit_rank1(np.abs(Yn), NO_SHRINK).kappa / k)).max()
    assert err_w < err_u / 5


def test_block_indices_are_contiguous_blocks():
    idx = block_bootstrap_indices(100, 25, 10, np.random.default_rng(0))
    assert idx.shape == (10, 100) and idx.min() >= 0 and idx.max() <= 99
    blocks = idx[:, :100].reshape(10, 4, 25)
    assert np.all(np.diff(blocks, axis=2) == 1)


def test_bootstrap_is_deterministic_and_covers_truth():
    k, z, Y = rank1(11, T=600)
    Y = np.abs(Y + np.random.default_rng(2).normal(0, 0.2, Y.shape))
    cfg = ComplianceConfig(n_boot=100)
    a, b = bootstrap_kappa(Y, cfg), bootstrap_kappa(Y, cfg)
    np.testing.assert_array_equal(a.samples, b.samples)
    assert np.all(a.low <= a.high)
    c = bootstrap_kappa(Y, ComplianceConfig(n_boot=100, seed=1))
    assert not np.array_equal(a.samples, c.samples)
    assert bootstrap_kappa(Y, ComplianceConfig(n_boot=0)) is None


def test_precision_shrinkage_keeps_a_noise_only_edge_from_dragging_the_others():
    rng = np.random.default_rng(4)
    k, z, Y = rank1(4, E=10, T=800, signed=True)
    Y[0] = 0.0  # a stiff segment: no bending signal at all ...
    Y = Y + rng.normal(0, 1.0, Y.shape)  # ... only noise
    count = fit_rank1(Y, ComplianceConfig(response="signed"))
    prec = fit_rank1(Y, ComplianceConfig(response="signed", shrinkage="precision"))
    # the noise-only edge is pulled toward 1 instead of toward 0
    assert abs(np.log(prec.kappa[0])) < abs(np.log(count.kappa[0]))
    # and the well-determined edges keep their ratios to each other
    ratio = lambda f: np.log(f.kappa[1:]) - np.log(f.kappa[1:]).mean()
    truth = np.log(k[1:]) - np.log(k[1:]).mean()
    assert np.sqrt(np.mean((ratio(prec) - truth) ** 2)) < 0.1


def test_precision_shrinkage_leaves_clean_edges_alone():
    k, z, Y = rank1(2, signed=True)
    Y = Y + np.random.default_rng(0).normal(0, 0.05, Y.shape)
    f = fit_rank1(Y, ComplianceConfig(response="signed", shrinkage="precision", n_iter=300, tol=1e-10))
    np.testing.assert_allclose(f.kappa, k, rtol=0.02)


def test_nanmedian_axis1_equals_numpy():
    """The bootstrap's starting excitation: the same numbers as np.nanmedian (NaN, inf, ties, empty columns)."""
    import warnings

    from rce_gtsam.model.compliance import nanmedian_axis1
    rng = np.random.default_rng(0)
    for trial in range(60):
        X = rng.standard_normal((int(rng.integers(1, 5)), int(rng.integers(1, 8)), int(rng.integers(1, 30))))
        X[rng.random(X.shape) < rng.random()] = np.nan
        if trial % 3 == 0:
            X[rng.random(X.shape) < 0.1] = np.inf
        if trial % 5 == 0:
            X = np.round(X)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            expected = np.nanmedian(X, axis=1)
        assert np.array_equal(nanmedian_axis1(X), expected, equal_nan=True)


def test_batch_with_a_shared_mask_fits_each_resample_as_alone():
    """Resamples sharing the missing-data mask and weights (the phase bootstrap's batches) share the mask's
    arrays; each one's fit is still exactly the fit of that resample alone."""
    rng = np.random.default_rng(1)
    E, T, B = 6, 120, 5
    z = np.abs(np.sin(np.arange(T) / 9.0)) * 4 + 0.5
    Y = rng.uniform(0.5, 2.0, E)[None, :, None] * z[None, None, :] + rng.normal(0, 0.4, (B, E, T))
    Y[:, rng.random((E, T)) < 0.1] = np.nan
    W = np.broadcast_to(rng.uniform(0.5, 1.5, (E, T)), (B, E, T))
    cfg = ComplianceConfig(response="signed", shrinkage="precision")
    batch = fit_rank1_batch(Y, cfg, W)
    for b in range(B):
        alone = fit_rank1_batch(Y[b:b + 1], cfg, W[b:b + 1])
        for x, y in zip(batch, alone):
            assert np.array_equal(x[b], y[0])


def test_names_that_moved_out_of_compliance_are_still_importable_from_it():
    """The bootstraps (model/uncertainty.py) and the phase surrogates (model/surrogates.py) were part of
    compliance.py; code that imports them from there (the diagnosis, notebooks, users' scripts) gets the very
    same objects, and an unknown name is still an AttributeError."""
    from rce_gtsam.model import compliance, surrogates, uncertainty
    from rce_gtsam.model.compliance import (BootstrapCI, bootstrap_kappa, draw_phases,  # noqa: F401
                                            residual_spectrum, surrogate_slice)

    for name in ("BootstrapCI", "BOOTSTRAP_CHUNK_ELEMENTS", "block_bootstrap_indices", "iter_block_bootstrap_indices",
                 "bootstrap_chunk", "excitation_dof", "small_sample_factor", "bootstrap_kappa",
                 "posterior_widening", "interval_about"):
        assert getattr(compliance, name) is getattr(uncertainty, name), name
    for name in ("phase_randomised_residuals", "draw_phases", "residual_spectrum", "centred_observed",
                 "surrogate_residuals", "surrogate_slice"):
        assert getattr(compliance, name) is getattr(surrogates, name), name
    assert "bootstrap_kappa" in dir(compliance)
    with pytest.raises(AttributeError, match="no_such_name"):
        compliance.no_such_name
