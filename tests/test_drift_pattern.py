"""Creep against tracker drift by where it sits along the branch (rce_gtsam.diagnosis.drift_pattern).

A node's tracking error, fast or slow, turns its own bend and the two beside it (+1, -2, +1); a joint's creep
turns its own bend alone. The test compares the layout of the segments' slow courses with that of the fast
noise: calibrated on drift of that geometry, and it must pass a creep of every joint's own.
"""

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy import signal

from _effect_data import diagnosed_recording
from rce_gtsam import effects
from rce_gtsam.diagnosis.drift_pattern import drift_pattern_test

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_drift_layout_real import plant, simulated  # noqa: E402

N_NODES, T = 14, 600
E = N_NODES - 2


def _node_errors(rng, tau=120.0, drift=1.0, white=1.0):
    """(N_NODES, T) across-branch errors of every node: white noise plus AR(1) drift (correlation time tau
    frames), growing toward the tip as a tracker's do."""
    a = np.exp(-1.0 / tau)
    slow = signal.lfilter([np.sqrt(1 - a * a)], [1, -a], rng.standard_normal((N_NODES, T + 600)), axis=1)[:, 600:]
    grow = np.linspace(1.0, 2.0, N_NODES)[:, None]
    return grow * (drift * slow + white * rng.standard_normal((N_NODES, T)))


def _bends(node_errors):
    """(E, T) the bend-angle errors the node errors give a straight chain of unit segments (+1, -2, +1)."""
    return node_errors[:-2] - 2 * node_errors[1:-1] + node_errors[2:]


def _p(R, kappa, seed=0):
    fit = SimpleNamespace(residuals=R, weights=np.ones_like(R), kappa=kappa)
    return drift_pattern_test(fit, effects.make("offset").heldout_time_basis(T), n_draws=1000, seed=seed).p


def test_drift_of_the_nodes_is_not_taken_for_a_creep():
    """Slow drift (a fifth of the record) and white noise of every node, through the bend geometry: p <= 0.05 on
    at most 10 of 100 records and p <= 0.01 on at most 4 (measured 8 and 3; over 500 other records 6.6 % and
    1.2 %, slightly above the nominal 5 % and 1 %: the null is drawn from the correlation estimated on the same
    record)."""
    rng = np.random.default_rng(0)
    kappa = np.exp(0.3 * rng.standard_normal(E))
    ps = np.array([_p(_bends(_node_errors(rng)), kappa) for _ in range(100)])
    assert np.sum(ps <= 0.05) <= 10 and np.sum(ps <= 0.01) <= 4


def test_a_creep_of_each_joints_own_on_the_same_drift_is_found():
    """The same drift plus a creep of each joint's own (random per joint, RMS over the segments 2.6 times that
    of the drift's own trends): p <= 0.05 on at least 5 of 10 (measured 6/10; the same drift alone 8 of 100)."""
    rng = np.random.default_rng(1)
    kappa = np.exp(0.3 * rng.standard_normal(E))
    tt = np.arange(T) / T
    ps = [_p(_bends(_node_errors(rng)) + 15.0 * rng.standard_normal(E)[:, None] * tt[None], kappa)
          for _ in range(10)]
    assert sum(p <= 0.05 for p in ps) >= 5


def test_missing_frames_a_course_along_kappa_and_a_constant_only_basis():
    """Missing entries stay missing; a course along kappa (the excitation's, which z takes) does not count; an
    offset without a creep (a constant only, set by the reference pose) has nothing to test."""
    rng = np.random.default_rng(2)
    kappa = np.exp(0.3 * rng.standard_normal(E))
    R = _bends(_node_errors(rng))
    base = _p(R, kappa)
    assert abs(_p(R + 2.0 * kappa[:, None] * (np.arange(T) / T)[None], kappa) - base) <= 0.05
    R[3, 100:180] = np.nan
    assert 0 < _p(R, kappa) <= 1
    fit = SimpleNamespace(residuals=R, weights=np.ones_like(R), kappa=kappa)
    assert drift_pattern_test(fit, effects.make("offset").__class__(trend=False).heldout_time_basis(T)) is None


def test_a_creep_the_other_checks_miss_is_named_for_its_layout_along_the_branch():
    """Offset + creep at 4x the simulator's default (seed 15): held-out RMSE 11 % lower with a fold t of 5.0,
    but its gain is within what phase surrogates of the residuals give (p = 0.47) and the two node-disjoint
    row sets share no course (p = 0.46); the segments' trends are laid out unlike a node's drift (p = 0.005).
    Before this test the offset was not named here, and the explanation says which check passed."""
    d = diagnosed_recording(15, "offset", 4)
    c = d.candidate("offset")
    assert c.extra["heldout_null_p"] > c.extra["heldout_null_threshold_p"]
    assert c.extra["shared_course_p"] > c.extra["shared_course_threshold_p"]
    assert c.extra["drift_pattern_p"] <= c.extra["drift_pattern_threshold_p"]
    assert d.verdict == "offset" and "not laid out as a node's tracking drift" in d.explanation
    assert "only partly checked on real footage" in d.explanation  # the assumption it rests on is said


def test_the_layout_assumption_asked_of_the_real_plants_gives_what_the_readme_quotes(shared_data):
    """The assumption on real footage (benchmarks/bench_drift_layout_real.py): the segment lengths, tracking
    error with no creep in it, and the bends' own check on the rank-1 baseline, p to the README's decimals."""
    quoted = {"plant_1": {"lengths raw": 0.47, "lengths smoothed": 0.17, "bends default": 0.031,
                          "bends paper": 0.14},
              "plant_2": {"lengths raw": 0.047, "lengths smoothed": 0.17, "bends default": 0.14,
                          "bends paper": 0.038}}
    for name, want in quoted.items():
        got = plant(shared_data / name)
        for k, v in want.items():
            decimals = len(str(v).split(".")[1])
            assert round(got[k], decimals) == v, (name, k, got[k])


def test_segment_lengths_of_simulated_tracks_do_not_reject_the_layout():
    """The length form of the test is calibrated where slow and fast errors are one node's (the simulator):
    p <= 0.05 on at most 3 of 20 effect-free recordings, raw tracks (1 of 20 measured; 3 of 100 over 100)."""
    hits = sum(simulated(s)["lengths raw"] <= 0.05 for s in range(20))
    assert hits <= 3
