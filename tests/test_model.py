import numpy as np
import pytest

from rce_gtsam import effects
from rce_gtsam.compliance import fit_rank1
from rce_gtsam.errors import InputError
from rce_gtsam.model import ResponseModel
from rce_gtsam.presets import ComplianceConfig

from _effect_data import synth


def test_baseline_matches_published_rank1_fit():
    Y, s, k, z, _ = synth(None, seed=3)
    cfg = ComplianceConfig(response="signed", n_iter=500, tol=1e-8)
    ref = fit_rank1(Y, cfg)
    fit = ResponseModel(prior_strength=cfg.prior_strength, tol=1e-8, max_iter=500).fit(Y, root_distance=s)
    np.testing.assert_allclose(np.abs(fit.kappa), ref.kappa, rtol=1e-4)
    assert np.isclose(np.exp(np.mean(np.log(np.abs(fit.kappa)))), 1.0)


def test_composition_and_immutability():
    base = ResponseModel()
    m = base + effects.Delay() + effects.Offset()
    assert base.effects == ()
    assert [e.name for e in m.effects] == ["delay", "offset"]
    assert m.add(effects.Nonlinear()).name == "rank1 + delay + nonlinear + offset"
    with pytest.raises(ValueError):
        m + effects.Offset()


def test_offset_fit_recovers_offsets_and_lowers_aic():
    Y, s, k, z, y = synth("offset", seed=1)
    f0 = ResponseModel().fit(Y, root_distance=s)
    f1 = (ResponseModel() + effects.Offset()).fit(Y, root_distance=s, init=f0)
    assert f1.aic < f0.aic and f1.rmse < f0.rmse
    assert np.sqrt(np.mean(np.log(np.abs(f1.kappa) / k) ** 2)) < np.sqrt(np.mean(np.log(np.abs(f0.kappa) / k) ** 2))
    p = f1.params
    assert "offset.c[0]" in p and p["offset.c[0]"].stderr > 0
    rep = f1.report()
    assert "[[Variables]]" in rep and "Akaike" in rep


def test_bad_input_is_an_input_error():
    with pytest.raises(InputError):
        ResponseModel().fit(np.ones(5))
    Y = np.ones((3, 10))
    Y[1] = np.nan
    with pytest.raises(InputError, match="row 1"):
        ResponseModel().fit(Y)
