"""The ideal oracle (rce_gtsam.diagnosis.ideal_oracle) on synthetic residuals with the tracker's noise structure
(a node's error enters three neighbouring bends as +1, -2, +1, slow in time), and the held-out schemes' row sets
(benchmarks/heldout_schemes.py) never let a node's noise reach both sides."""

import sys
from pathlib import Path

import numpy as np
import pytest

from rce_gtsam.diagnosis.ideal_oracle import signature_test
from rce_gtsam.model.row_sets import shared_node_matrix

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import heldout_schemes  # noqa: E402

E, T = 18, 450


def node_noise(rng, sd=1.4):
    """(E, T) bend-angle noise of a chain: node errors smoothed over ~10 frames, each entering +1, -2, +1."""
    nodes = rng.standard_normal((E + 2, T + 40))
    k = np.exp(-0.5 * (np.arange(-20, 21) / 6.0) ** 2)
    nodes = np.array([np.convolve(r, k / np.linalg.norm(k), mode="valid") for r in nodes])[:, :T]
    bends = nodes[:-2] - 2 * nodes[1:-1] + nodes[2:]
    return sd * bends / bends.std()


def signature(rng, amp):
    """(E, T) a second excitation's pattern: a smooth gain along the branch times a slow course (deg)."""
    mu = np.sin(np.linspace(0, np.pi, E)) - 0.3
    w = np.convolve(rng.standard_normal(T + 60), np.ones(60) / np.sqrt(60), mode="valid")[:T]
    S = np.outer(mu, w)
    return amp * S / np.sqrt(np.mean(S ** 2))


def test_the_known_signature_is_found_at_a_third_of_the_noise():
    rng = np.random.default_rng(1)
    S = signature(rng, 0.45)
    r = signature_test(node_noise(rng) + S, S, seed=0, n_surrogates=999)
    assert r.p <= 0.005 and r.z > 2


def test_its_false_alarms_follow_the_level_on_noise_alone_and_it_is_one_sided():
    rng = np.random.default_rng(2)
    ps, flipped = [], []
    for _ in range(20):
        S, R = signature(rng, 0.45), node_noise(rng)
        ps.append(signature_test(R, S, seed=3, n_surrogates=199).p)
        flipped.append(signature_test(R - S, S, seed=3, n_surrogates=199).p)
    # binomial(20, 0.05): 5 or more below 0.05 has probability 0.003
    assert sum(p <= 0.05 for p in ps) <= 4
    assert 0.25 < np.mean(ps) < 0.75
    assert min(flipped) > 0.5  # the signature with the wrong sign is no evidence for it


def test_missing_entries_are_allowed_and_a_wrong_shape_is_refused():
    rng = np.random.default_rng(4)
    S = signature(rng, 0.45)
    R = node_noise(rng) + S
    R[3, 100:160] = np.nan
    assert signature_test(R, S, seed=0, n_surrogates=199).p <= 0.01
    with pytest.raises(ValueError, match="differ in shape"):
        signature_test(R[:, :-1], S)


def test_bcv_row_sets_share_no_node_and_score_every_row():
    s = np.linspace(0.05, 1.0, E)
    sets = heldout_schemes.bcv_sets(s)
    shared = shared_node_matrix(s)
    assert sorted(np.concatenate([B for _, B in sets]).tolist()) == list(range(E))
    for A, B in sets:
        assert not shared[np.ix_(A, B)].any()
        assert len(A) >= E - len(B) - 4  # only the rows next to B are left out


def test_joint_posterior_recovers_the_latents_without_noise_or_prior():
    rng = np.random.default_rng(5)
    K = rng.standard_normal((6, 2))
    theta = rng.standard_normal((2, 30))
    y = K @ theta
    y[0, 3] = np.nan
    corr = 0.5 * np.eye(6) + 0.5 * np.exp(-np.abs(np.subtract.outer(np.arange(6), np.arange(6))))
    got = heldout_schemes.joint_posterior(K, corr, y, np.zeros(2))
    assert np.allclose(got, theta, atol=1e-8)


def test_the_benchmark_names_a_bad_option_before_any_work():
    """A null strength with no effect case to borrow its signature from is refused before the (minutes of) cases."""
    import subprocess
    args, named = ["--mults", "1,2", "--null-mult", "3"], "--null-mult 3"
    r = subprocess.run([sys.executable, str(REPO / "benchmarks" / "beam_ideal_oracle.py"), *args],
                       capture_output=True, text=True, timeout=60, env={"PYTHONPATH": str(REPO), "PATH": ""})
    assert r.returncode == 2 and named in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
