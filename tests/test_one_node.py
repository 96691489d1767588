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
