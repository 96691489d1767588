"""Every registered effect follows the protocol of :mod:`rce_gtsam.effects.base` (issue 11, item 5).

A new effect is one file plus ``effects.register(MyEffect)``; this test then checks it like the built-ins:
description, parameters, a fit that uses the term, its own residual evidence, its explanation, and the
diagnosis naming it on clean data that contain it.
"""

import math

import numpy as np
import pytest

from rce_gtsam import effects
from rce_gtsam.diagnosis.diagnose import diagnose, residual_statistics
from rce_gtsam.diagnosis.statistics import ResidualContext
from rce_gtsam.effects.base import Effect, Parameter
from rce_gtsam.model import ResponseModel
from _effect_data import default_strength, synth

BUILTIN = list(effects.EFFECT_NAMES)


def _finite_numbers(d):
    for v in d.values():
        a = np.asarray(v, dtype=float)
        assert np.all(np.isfinite(a)), d


@pytest.mark.parametrize("name", BUILTIN)
def test_effect_describes_itself(name):
    eff = effects.make(name)
    assert isinstance(eff, Effect) and eff.name == name
    assert eff.kind in {"operator", "output", "additive"}
    for text in (eff.equation, eff.fitting, eff.physics):
        assert isinstance(text, str) and len(text) > 20
    assert "()" not in eff.physics and "--" not in eff.physics  # interface-neutral physics text
    ps = eff.parameters(6)
    assert all(isinstance(p, Parameter) and p.unit for p in ps)


@pytest.mark.parametrize("name", BUILTIN)
def test_effect_fits_owns_evidence_and_explains(name):
    Y, s, k, z, y = synth(name, seed=3, E=10, T=400, noise=0.05, strength=3 * default_strength(name))
    base = ResponseModel().fit(Y, root_distance=s)
    ext = (ResponseModel() + effects.make(name)).fit(Y, root_distance=s)
    assert ext.wsse < base.wsse  # the term explains part of what the rank-1 model cannot
    assert ext.model.effects[0].memory_frames(ext.states[0]) >= 0
    stats = effects.make(name).evidence(ResidualContext.from_fit(base))
    assert isinstance(stats, dict) and stats
    _finite_numbers(stats)
    summary = ext.effect_summary()[name]
    text = effects.make(name).explain(summary, stats)
    assert isinstance(text, str) and len(text) > 20 and "nan" not in text.lower()
    assert residual_statistics(base, [name])[name].keys() == stats.keys()


@pytest.mark.parametrize("name", BUILTIN)
def test_a_form_of_another_effect_reports_that_effect(name):
    """Effect.finding: an effect that is another form of a library effect (resonances: dynamics with each joint's
    own frequency) names a registered effect of its own kind; the verdict then reports that effect."""
    eff = effects.make(name)
    if eff.finding is None:
        assert effects.finding(name) == name
    else:
        assert eff.finding != name and eff.finding in effects.CANDIDATES
        assert effects.make(eff.finding).kind == eff.kind and effects.finding(name) == eff.finding


@pytest.mark.parametrize("name", BUILTIN)
def test_alternative_starts_are_valid_states_the_model_fits_from(name):
    """Effect.alternative_starts (optional): every proposed start has the state's shape, parameters inside their
    bounds, and the model fits from it; solve_from_starts then keeps the start with the smallest cross-prediction
    error (and an effect without alternatives gets exactly its plain fit)."""
    from rce_gtsam.diagnosis.diagnose import node_disjoint_split, shared_node_matrix
    from rce_gtsam.model import validate_inputs
    from rce_gtsam.model.starts import cross_prediction_error, solve_from_starts
    Y, s, *_ = synth(name, seed=2, E=12, T=300, noise=0.3)
    Y, W, s = validate_inputs(Y, None, s)
    eff = effects.make(name)
    model = ResponseModel() + eff
    base = ResponseModel().solve(Y, W, s)
    plain = model.solve(Y, W, s, start=base.warm_start(), max_iter=10)
    alts = eff.alternative_starts(plain.states[0])
    bounds = {p.name: p for p in eff.parameters(len(s))}
    for st in alts:
        assert set(st["params"]) == set(plain.states[0]["params"])
        for k, v in st["params"].items():
            assert np.all((np.asarray(v) >= bounds[k].lower) & (np.asarray(v) <= bounds[k].upper)), (k, v)
    halves = node_disjoint_split(s, shared_node_matrix(s), 0)
    fit, record = solve_from_starts(model, Y, W, s, halves, start=base.warm_start(), max_iter=10)
    if not alts:
        assert record == {} and np.array_equal(fit.kappa, plain.kappa) and fit.wsse == plain.wsse
    else:
        assert len(record["errors"]) == 1 + len(alts)
        assert cross_prediction_error(fit, halves) == pytest.approx(min(record["errors"]))
        # the maximum-likelihood fit among the starts, which the encompassing tests use
        ml = record["lowest_in_sample_fit"]
        assert ml.wsse <= fit.wsse and ml.wsse <= plain.wsse * (1 + 1e-9)
        assert (record["lowest_in_sample"] == record["chosen"]) == (ml is fit)


@pytest.mark.parametrize("name", BUILTIN)
def test_an_effect_that_can_be_undone_undoes_its_own_operator(name):
    """Effect.align (optional; the encompassing test needs it of the simpler candidate): where it is not None,
    it moves the effect's own fitted operator's output back onto the excitation's clock."""
    Y, s, k, z, y = synth(name, seed=3, E=10, T=400, noise=0.05, strength=3 * default_strength(name))
    ext = (ResponseModel() + effects.make(name)).fit(Y, root_distance=s)
    eff, state = ext.model.effects[0], ext.states[0]
    if eff.align(np.zeros((1, 4)), state, np.zeros(1)) is None:
        return
    assert eff.kind == "operator"
    X = eff.apply(np.repeat(ext.z[None], len(s), axis=0), state, ext.view())
    A = eff.align(X, state, s)
    ok = np.isfinite(A)
    assert ok.mean() > 0.8
    assert np.abs(A - ext.z[None])[ok].max() < 0.05 * np.abs(ext.z).max()


@pytest.mark.slow
@pytest.mark.parametrize("name", BUILTIN)
def test_diagnosis_names_each_effect_on_clean_data(name):
    # 18 segments x 600 frames, 8 folds: shorter records with 4 folds leave too little training data around a
    # test block for per-edge terms (an offset's trend extrapolated over 100+ frames)
    Y, s, k, z, y = synth(name, seed=5, E=18, T=600, noise=0.03, strength=3 * default_strength(name))
    d = diagnose(Y, root_distance=s, effects=[name, "offset" if name != "offset" else "nonlinear"])
    assert d.verdict == effects.finding(name) and d.verdict_effect == name, d.report()
    assert d.as_dict()["verdict"] == d.verdict and d.as_dict()["verdict_effect"] == name
    if d.verdict != name:  # a form of another effect: the report says which form
        assert f"{d.verdict} (in the form {name})" in d.report()


class Step(Effect):
    """A researcher's own effect, written in one file: a per-edge step at a shared frame (a touch)."""

    name = "step_test"
    kind = "additive"
    equation = "y_e(t) = kappa_e z_t + h_e [t >= t0]"
    fitting = "t0 on a grid of frames; h_e by per-edge least squares of the partial residual"
    physics = ("something touched or released the branch at one moment, shifting every joint's rest angle "
               "at once; check the footage around that frame.")

    def parameters(self, n_edges):
        return (Parameter("h", "deg", per_edge=True, description="step height"),
                Parameter("t0", "frames", description="step frame"))

    def init(self, view):
        return self.update({"params": {"h": np.zeros(view.E), "t0": np.array(view.T / 2)}, "latents": {}},
                           view, frozen=False)

    def update(self, state, view, frozen):
        if frozen:
            return state
        i = view.index_of(self)
        target = view.partial_target(i) if i is not None else view.Y0 - view.predict()
        R = np.where(view.W > 0, target, np.nan)  # what this term must explain
        best = None
        for t0 in range(10, view.T - 10, max(1, view.T // 40)):
            step = (np.arange(view.T) >= t0).astype(float)
            ok = np.isfinite(R)
            h = np.array([np.sum(np.where(ok[e], R[e], 0) * step) / max(np.sum(step * ok[e]), 1) -
                          np.sum(np.where(ok[e], R[e], 0) * (1 - step)) / max(np.sum((1 - step) * ok[e]), 1)
                          for e in range(view.E)])
            sse = np.nansum((R - h[:, None] * step[None]) ** 2)
            if best is None or sse < best[0]:
                best = (sse, h, t0)
        return {"params": {"h": best[1], "t0": np.array(float(best[2]))}, "latents": {}}

    def additive(self, state, view):
        step = (np.arange(view.T) >= float(state["params"]["t0"])).astype(float)
        return state["params"]["h"][:, None] * step[None, :]

    def evidence(self, ctx):
        d = np.nanmean(ctx.R[:, ctx.R.shape[1] // 2:], axis=1) - np.nanmean(ctx.R[:, : ctx.R.shape[1] // 2], axis=1)
        return {"half_difference_rms_deg": float(np.sqrt(np.mean(d ** 2)))}

    def explain(self, summary, statistics):
        return (f"A step at frame {summary.get('t0', {}).get('value', math.nan):.0f}; baseline residual halves "
                f"differ by {statistics['half_difference_rms_deg']:.2f} deg RMS.")


def test_a_new_effect_is_one_class_and_a_registry_line():
    effects.register(Step)
    try:
        assert "step_test" in effects.names()
        assert "step_test" in effects.CANDIDATES
        from rce_gtsam.diagnosis.io import parse_effect_names
        assert parse_effect_names("step_test") == ("step_test",)
        with pytest.raises(ValueError):
            effects.register(type("Other", (Step,), {}))  # same name, another class
        test_effect_describes_itself("step_test")
        rng = np.random.default_rng(0)
        z = np.sin(np.arange(300) / 9.0)
        Y = np.outer(np.linspace(0.5, 2, 8), z) + 0.05 * rng.standard_normal((8, 300))
        Y[:, 180:] += np.linspace(1, -1, 8)[:, None]  # a touch at frame 180
        fit = (ResponseModel() + effects.make("step_test")).fit(Y)
        assert abs(fit.effect_summary()["step_test"]["t0"]["value"] - 180) <= 8
        assert fit.rmse < 0.5 * ResponseModel().fit(Y).rmse
    finally:
        effects.CANDIDATES.pop("step_test", None)
    assert "step_test" not in effects.names()
