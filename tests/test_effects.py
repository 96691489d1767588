import numpy as np

from rce_gtsam import effects
from rce_gtsam.model import FitView, ResponseModel
from rce_gtsam.simulate import delayed, oscillator_response


def _view(model, E=4, T=200):
    s = np.linspace(0, 1, E)
    Y = np.zeros((E, T))
    return FitView(model, Y, np.ones((E, T)), s, np.ones(T, bool), np.ones(E), np.zeros(T), [])


def test_delay_operator_matches_simulator_and_adjoint():
    eff = effects.Delay()
    v = _view(ResponseModel() + eff)
    t = np.arange(200)
    z = np.sin(2 * np.pi * t / 40.0)
    st = {"params": {"tau": np.array(3.0)}, "latents": {}}
    X = eff.apply(np.broadcast_to(z, (4, 200)).copy(), st, v)
    for e in range(4):
        ref = delayed(z, 3.0 * v.s[e])
        assert np.max(np.abs(X[e, 10:] - ref[10:])) < 2e-3
    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((4, 200)), rng.standard_normal((4, 200))
    assert np.isclose(np.sum(eff.apply(A, st, v) * B), np.sum(A * eff.apply_T(B, st, v)))


def test_dynamics_operator_matches_simulator_and_adjoint():
    eff = effects.Dynamics()
    v = _view(ResponseModel() + eff)
    st = {"params": {"omega_root": np.array(0.9), "omega_tip": np.array(0.3), "zeta": np.array(0.2)}, "latents": {}}
    rng = np.random.default_rng(1)
    u = np.cumsum(rng.standard_normal(200)) * 0.1
    u -= u[0]
    X = eff.apply(np.broadcast_to(u, (4, 200)).copy(), st, v)
    om = eff.omegas(st, v.s)
    for e in range(4):
        assert np.allclose(X[e], oscillator_response(u, om[e], 0.2), atol=1e-8)
    A, B = rng.standard_normal((4, 200)), rng.standard_normal((4, 200))
    assert np.isclose(np.sum(eff.apply(A, st, v) * B), np.sum(A * eff.apply_T(B, st, v)))


def test_nonlinear_output_is_odd_and_saturates():
    eff = effects.Nonlinear()
    st = {"params": {"c": np.array(1.0)}, "latents": {}}
    u = np.linspace(-5, 5, 11)
    g, dg = eff.output(u, st)
    assert np.allclose(g, -g[::-1]) and np.all(np.abs(g) <= 1.0 + 1e-12) and np.all(dg <= 1)
    g0, _ = eff.output(u, {"params": {"c": np.array(0.0)}, "latents": {}})
    assert np.allclose(g0, u)


def test_every_effect_documents_its_physics():
    for name in effects.EFFECT_NAMES:
        e = effects.make(name)
        assert e.name == name and e.equation and e.fitting and e.parameters(3)
        assert "Physics" in __import__(type(e).__module__, fromlist=["x"]).__doc__
