"""Synthetic bend-response matrices with a hidden effect (the simulator's equations + noise), for tests."""

import numpy as np
from scipy import signal

from rce_gtsam.sim import simulate as sim


#: candidates that are another form of a simulated effect: (the simulator's effect, its form)
SIMULATED_AS = {"resonances": ("dynamics", "scattered")}


def default_strength(effect):
    """The simulator's default strength of ``effect`` (of the effect it is a form of)."""
    return sim.EFFECT_DEFAULTS[SIMULATED_AS.get(effect, (effect,))[0]]


def synth(effect=None, seed=0, E=12, T=600, noise=0.3, strength=None):
    ss = np.random.SeedSequence(seed)
    r1, r2, r3, r4 = (np.random.default_rng(s) for s in ss.spawn(4))
    s = np.sort(r1.uniform(0.05, 1, E))
    s[-1] = 1.0
    logk = r1.normal(0, 0.5, E)
    kappa = np.exp(logk - logk.mean())
    z = sim.make_excitation(T, 30.0, r2, rms_deg=1.5)
    st = dict(sim.EFFECT_DEFAULTS)
    simulated, form = SIMULATED_AS.get(effect, (effect, None))
    if strength is not None and effect is not None:
        st[simulated] = strength
    y, _ = sim.bend_response(kappa, s, z, () if effect is None else (simulated,), st, 30.0, r3,
                             forms=None if form is None else {simulated: form})
    b, a = signal.butter(2, 0.1)
    n = noise * (r4.standard_normal((E, T)) + 2 * signal.filtfilt(b, a, r4.standard_normal((E, T)), axis=1))
    Y = y + n
    Y[r4.uniform(size=(E, T)) < 0.02] = np.nan
    return Y, s, kappa, z, y


def diagnosed_recording(seed, effect=None, strength_mult=1.0, candidates=("offset",), **simulation):
    """The diagnosis (default preset, ``candidates`` only) of a simulated recording through the whole pipeline:
    ``effect`` hidden at ``strength_mult`` times the simulator's default, 900 frames, other
    :class:`~rce_gtsam.sim.simulate.SimulationConfig` fields from ``simulation`` (fps=60, ...)."""
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.presets import get_preset

    kw = {} if effect is None else {"effects": (effect,),
                                    "effect_strength": {effect: strength_mult * sim.EFFECT_DEFAULTS[effect]}}
    simulated = sim.simulate(sim.SimulationConfig(seed=seed, n_frames=900, **kw, **simulation))
    r = analyze(simulated.tracks, simulated.graph, preset="default", n_boot=0).response
    return diagnose(r.Y, weights=r.weights, root_distance=r.root_distance, edge_labels=r.edge_labels,
                    effects=list(candidates), config=get_preset("default").compliance)
