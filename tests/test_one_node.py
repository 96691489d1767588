"""The one-node check (rce_gtsam.diagnosis.one_node): a named effect must not rest on one tracked node."""

import numpy as np

from rce_gtsam.diagnosis.diagnose import diagnose
from rce_gtsam.diagnosis.one_node import carrying_node, holds, node_shares, rows_without

from _effect_data import synth


def chain_nodes(E):
    """Bend j of a chain turns at node j + 1 between nodes j and j + 2."""
    return [{j, j + 1, j + 2} for j in range(E)]


def test_the_carrying_node_is_the_one_whose_bends_hold_the_gain():
    rb = np.ones((5, 10))
    rc = rb.copy()
    rc[2] = 0.0  # the candidate takes all of bend 2's residual
    nodes = chain_nodes(5)
    shares = node_shares(rb, rc, nodes)
    assert shares[2] == shares[3] == shares[4] == 1.0 and shares[0] == 0.0
    assert carrying_node(rb, rc, nodes) == (2, 1.0)  # ties: the lowest id
    assert carrying_node(rb, rb, nodes) is None  # no gain, no node
    worse = rb.copy()
    worse[0] = 2.0  # the candidate loses on bend 0 more than it gains on bend 2: the gaining bends still locate it
    worse[2] = 0.0
    assert carrying_node(rb, worse, nodes) == (2, 1.0)
    assert rows_without(3, nodes).tolist() == [True, False, False, False, True]
    labelled = [{"\x00root?", 0, 1}, {0, 1, 2}]  # a node id need not be a number (the root's placeholder)
    rc2 = np.ones((2, 10))
    rc2[0] = 0.0
    assert carrying_node(np.ones((2, 10)), rc2, labelled) == (0, 1.0)  # tie with 1 and the label: numbers first


def test_the_window_where_the_nodes_bends_gain_most():
    from rce_gtsam.diagnosis.one_node import gain_window
    rb = np.ones((3, 100))
    rc = rb.copy()
    rc[1, 40:70] = 0.0
    rows = np.array([False, True, False])
    assert gain_window(rb, rc, rows, frames=np.arange(100) + 1000, width=30) == (1040, 1069)
    assert gain_window(rb, rb, rows) == ()


def test_the_rule_is_a_sign():
    assert holds(0.4, 0.2) and not holds(-0.1, 0.5) and not holds(1.5, -0.3)
    assert holds(float("nan"), float("nan"))  # the check could not run: nothing is withheld


def test_a_slow_course_per_segment_must_stay_significant_without_the_node():
    from rce_gtsam.diagnosis.one_node import OneNodeCheck, one_node_text
    lag = OneNodeCheck("delay", 5, 0.4, ("4->5",), fold_t=1.4, heldout_gain_pct=0.3, significant=False)
    offset = OneNodeCheck("offset", 5, 0.4, ("4->5",), fold_t=1.4, heldout_gain_pct=0.3, significant=False,
                          courses=True)
    assert lag.holds and not offset.holds
    assert OneNodeCheck("offset", 5, 0.4, ("4->5",), 2.9, 4.0, significant=True, courses=True).holds
    assert "no longer significant" in one_node_text(offset) and "drift" in one_node_text(offset)
    assert offset.as_dict()["per_segment_courses"] and offset.as_test().name == "one_node"
    assert OneNodeCheck.from_dict(offset.as_dict()) == offset


def _tracker_second_mode(seed=2, E=16):
    """Effect-free bends plus two nodes' tracking errors that follow the motion (the same nonlinear course of the
    excitation), one node's much larger: the +1, -2, +1 pattern on the three bends each enters."""
    Y, s, kappa, z, y = synth(None, seed=seed, E=E)
    course = np.abs(z) - np.mean(np.abs(z))
    course /= np.std(course)
    for node, size in ((11, 3.0), (4, 0.3)):
        for j, w in zip((node - 2, node - 1, node), (1.0, -2.0, 1.0)):
            Y[j] += size * w * course
    return Y, s


def test_a_second_mode_that_rests_on_one_node_is_not_named():
    Y, s = _tracker_second_mode()
    nodes = chain_nodes(Y.shape[0])
    unchecked = diagnose(Y, root_distance=s, effects=["second_mode"], edge_nodes=nodes, check_one_node=False)
    assert unchecked.verdict == "second_mode"  # every other test passes on it
    d = diagnose(Y, root_distance=s, effects=["second_mode"], edge_nodes=nodes)
    assert d.verdict is None
    check = d.settings["one_node"]
    assert check["node"] == 11 and not check["holds"] and check["heldout_gain_pct"] <= 0
    assert d.settings["verdict_withheld"] == {"effect": "second_mode", "rule": "one_node"}
    assert "node 11" in d.explanation and "the tracker, not physics" in d.explanation
    lo, hi = check["frames"]
    assert hi - lo == 29 and f"frames {lo}-{hi}" in d.explanation
    assert d.candidate("second_mode").tests["one_node"].name == "one_node"


def test_a_second_excitation_of_the_whole_branch_holds_without_any_one_node():
    Y, s, *_ = synth("second_mode", seed=0, E=16)
    d = diagnose(Y, root_distance=s, effects=["second_mode"], edge_nodes=[{i} for i in range(16)])
    assert d.verdict == "second_mode"
    check = d.settings["one_node"]
    assert check["holds"] and check["heldout_gain_pct"] > 0 and check["fold_t"] > 0
    assert "does not rest on one tracked node" in d.explanation


def _chain_geometry(n_nodes, length=20.0, bend_deg=6.0):
    """Rest positions of a gently curved chain (node ids 0..n-1) and its bends as (grandparent, joint, child)."""
    heading = np.cumsum(np.full(n_nodes - 1, np.radians(bend_deg)))
    steps = length * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    xy = np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])
    return {i: xy[i] for i in range(n_nodes)}, [(j, j + 1, j + 2) for j in range(n_nodes - 2)]


def test_the_bend_jacobian_is_the_turning_angles_derivative():
    from rce_gtsam.diagnosis.one_node import bend_jacobian

    rest, bends = _chain_geometry(6, bend_deg=17.0)

    def turning(p):
        out = []
        for g, m, c in bends:
            r1, r2 = p[m] - p[g], p[c] - p[m]
            out.append(np.degrees(np.arctan2(r2[1], r2[0]) - np.arctan2(r1[1], r1[0])))
        return np.array(out)

    J = bend_jacobian(bends, rest)
    for node in rest:
        for axis in (0, 1):
            moved = {k: v.copy() for k, v in rest.items()}
            moved[node][axis] += 1e-6
            assert np.allclose((turning(moved) - turning(rest)) / 1e-6, J[node][:, axis], atol=1e-4)
    rest[3] = rest[2].copy()  # a segment with no length: no Jacobian
    assert bend_jacobian(bends, rest) is None


def test_the_projected_row_keeps_the_branch_and_none_of_the_nodes_error():
    from rce_gtsam.diagnosis.one_node import bend_jacobian, projected_row

    rest, bends = _chain_geometry(8)
    E, T = len(bends), 400
    rng = np.random.default_rng(0)
    kappa = np.exp(rng.normal(0, 0.4, E))
    z = np.cumsum(rng.normal(0, 0.2, T))
    J = bend_jacobian(bends, rest)
    error = np.cumsum(rng.normal(0, 0.3, (T, 2)), axis=0)  # node 4's error, any course, along and across
    Y = kappa[:, None] * z[None] + J[4] @ error.T
    nodes = [set(b) for b in bends]
    y, w, s_row = projected_row(Y, None, np.linspace(0.1, 1, E), 4, nodes, J, kappa)
    slope = (y @ z) / (z @ z)
    assert slope > 0.5 * np.linalg.norm(kappa[~rows_without(4, nodes)])  # most of the branch's response is kept
    assert np.allclose(y, slope * z, atol=1e-9)  # and none of the node's error
    assert np.all(w == 1.0) and 0.1 < s_row < 1.0
    Y[3, 7] = np.nan
    assert np.isnan(projected_row(Y, None, np.linspace(0.1, 1, E), 4, nodes, J, kappa)[0][7])
    assert projected_row(Y, None, np.linspace(0.1, 1, E), 0, nodes, J, kappa) is None  # the root enters one bend
    assert projected_row(Y, None, np.linspace(0.1, 1, E), 4, nodes, None, kappa) is None  # geometry unknown


def test_a_second_mode_resting_on_one_node_stays_unnamed_with_the_projection():
    """With the geometry known the check keeps the combination of node 11's bends that its error cannot move: the
    tracker's second mode (the +1, -2, +1 pattern across a straight stem) is still not named."""
    from rce_gtsam.diagnosis.one_node import bend_jacobian

    Y, s = _tracker_second_mode()
    E = Y.shape[0]
    rest, bends = _chain_geometry(E + 2, bend_deg=0.0)
    nodes = chain_nodes(E)
    d = diagnose(Y, root_distance=s, effects=["second_mode"], edge_nodes=nodes,
                 node_sensitivity=bend_jacobian(bends, rest))
    check = d.settings["one_node"]
    assert d.verdict is None and check["node"] == 11 and check["projected"] and not check["holds"]
    assert "keeping only the combination of them no error of node 11 can move" in d.explanation


def test_an_analysis_hands_the_check_its_geometry():
    """``rce diagnose`` (diagnose_inputs) gives the check each node's Jacobian at the analysis' rest pose."""
    from rce_gtsam.diagnosis.io import diagnose_inputs
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.simulate import SimulationConfig, simulate

    sim = simulate(SimulationConfig(n_nodes=8, n_frames=150, seed=3))
    result = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    kw = diagnose_inputs(result)
    J, nodes = kw["node_sensitivity"], kw["edge_nodes"]
    E = kw["Y"].shape[0]
    assert set(J) == {n for t in nodes for n in t} and all(a.shape == (E, 2) for a in J.values())
    for j, t in enumerate(nodes):  # a bend moves only with its own three nodes, and its joint moves it most
        assert all(np.allclose(J[n][j], 0.0) for n in J if n not in t)
        assert np.linalg.norm(J[t[1]][j]) > max(np.linalg.norm(J[t[0]][j]), np.linalg.norm(J[t[2]][j]))
