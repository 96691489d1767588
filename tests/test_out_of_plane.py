"""The out_of_plane effect (issue #39, part 2): segment lengths name a swing out of the branch plane.

The length channel's test (a course shared by node-disjoint segments beyond the excitation, phase-surrogate null),
the effect's protocol (a zero term without data, a fitted term that predicts the bending with data), its own
family (the other candidates' Bonferroni count unchanged), and the diagnosis on the 3-D simulator's recordings
through the pipeline and ``rce diagnose``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rce_gtsam import effects
from rce_gtsam.diagnosis.diagnose import diagnose
from rce_gtsam.diagnosis.io import diagnose_result
from rce_gtsam.diagnosis.length_channel import ALPHA_OOP, out_of_plane_test, swing_course
from rce_gtsam.effects.out_of_plane import OutOfPlane
from rce_gtsam.model import ResponseModel
from rce_gtsam.pipeline import analyze
from rce_gtsam.sim.artifacts import ArtifactConfig
from rce_gtsam.sim.simulate import SimulationConfig, simulate

from length_fixtures import chain_channel, smooth_course

SMALL = dict(n_nodes=12, n_frames=300)


def test_length_test_tells_a_shared_course_from_node_wise_errors():
    """Node errors that follow the excitation (slide: +1 on one segment, -1 on the next, a multiple of z) are
    removed or stay within a set; a course common to every segment (a swing) is found."""
    rng = np.random.default_rng(0)
    S, T = 14, 400
    z, w = smooth_course(rng, T), smooth_course(rng, T)
    node_err = rng.standard_normal((S + 1, 1)) * 0.02 * z[None] + 0.01 * rng.standard_normal((S + 1, T))
    nodewise = np.diff(node_err, axis=0)  # each segment: its child's error minus its parent's
    null = out_of_plane_test(chain_channel(nodewise), z, seed=0)
    swing = out_of_plane_test(chain_channel(nodewise + 0.004 * np.arange(1, S + 1)[:, None] * w[None]), z, seed=0)
    assert null is not None and null.p > 0.05
    assert swing.p <= ALPHA_OOP and swing.same_sign_share == 1.0 and swing.tip_growth > 0.5
    # held out: the other set's course predicts a set's lengths where there is a swing, and not otherwise
    assert swing.heldout_gain_pct > 30.0 and null.heldout_gain_pct < 2.0
    # the course it estimates is the shared one
    assert abs(np.corrcoef(swing_course(chain_channel(nodewise + 0.004 * np.arange(1, S + 1)[:, None] * w[None]),
                                        z), w)[0, 1]) > 0.9


def test_heldout_length_gain_scores_each_segment_in_its_own_units():
    """A swing in every segment, and the segments at three neighbouring nodes where the tracker failed grossly (relative
    length changes of order 1, node-wise): summed in relative length those three outweigh the rest and the gain
    falls to about 0 (the user's path had -3.0 %); scored per segment it stays large. Without a swing it stays
    near 0 either way."""
    rng = np.random.default_rng(3)
    S, T = 14, 400
    z, w = smooth_course(rng, T), smooth_course(rng, T)
    node_err = 0.01 * rng.standard_normal((S + 1, T))
    node_err[12:15] += 0.5 * rng.standard_normal((3, T))  # nodes 12-14 lost and re-found far off now and then
    nodewise = np.diff(node_err, axis=0)

    swing = nodewise + 0.01 * np.arange(1, S + 1)[:, None] * w[None]
    assert out_of_plane_test(chain_channel(swing), z, seed=0).heldout_gain_pct > 30.0  # summed (as before): 4.9 %
    assert out_of_plane_test(chain_channel(nodewise), z, seed=0).heldout_gain_pct < 2.0


def test_without_lengths_the_term_is_zero_and_never_named():
    rng = np.random.default_rng(1)
    E, T = 8, 300
    z = smooth_course(rng, T)
    kappa = np.exp(rng.normal(0, 0.4, E))
    Y = kappa[:, None] * z[None] + 0.2 * rng.standard_normal((E, T))
    eff = effects.make("out_of_plane")
    assert isinstance(eff, OutOfPlane) and eff.own_family and eff.own_family_test(None) is None
    assert not eff.available and eff.evidence(None) == {}
    d = diagnose(Y, effects=["offset", eff], n_folds=8)
    assert [c.effect for c in d.candidates] == ["offset"] and d.verdict != "out_of_plane"
    base = ResponseModel().fit(Y)
    ext = (ResponseModel() + eff).fit(Y)
    np.testing.assert_allclose(ext.predict(), base.predict(), atol=1e-6)


def _swing_and_second(rng, second: float):
    """(Y (E, T) deg, the swing's length channel, z): bends carry kappa z, a swing course w with per-edge gains
    (the lengths carry w too, growing toward the tip) and, with ``second`` > 0, a second excitation v independent
    of w with its own mode shape."""
    E, T = 12, 450
    z, w, v = smooth_course(rng, T), smooth_course(rng, T), smooth_course(rng, T)
    kappa = np.exp(rng.normal(0, 0.4, E))
    g, m = 0.6 * rng.standard_normal(E), second * rng.standard_normal(E)
    Y = kappa[:, None] * z[None] + g[:, None] * w[None] + m[:, None] * v[None] + 0.2 * rng.standard_normal((E, T))
    rel = 0.004 * np.arange(1, E + 2)[:, None] * w[None] + 0.01 * rng.standard_normal((E + 1, T))
    return Y, chain_channel(rel), z


def test_with_lengths_the_term_predicts_the_bending_and_keeps_the_others_alpha():
    """Synthetic: bends carry a swing course w with per-edge gains; the lengths carry w too. The term lowers the
    held-out error and is supported; the bend-residual candidates' Bonferroni count is what it is without it. The
    free second excitation, which fits the same course from the bends, is supported too, but refitted beside the
    out_of_plane term it no longer lowers the held-out error (verdict.weigh_beside_own): out_of_plane is the
    verdict and the explanation says why second_mode is not."""
    Y, channel, z = _swing_and_second(np.random.default_rng(2), second=0.0)
    eff = OutOfPlane(channel, z)
    with_it = diagnose(Y, effects=["offset", "second_mode", eff], n_folds=8)
    without = diagnose(Y, effects=["offset", "second_mode"], n_folds=8)
    assert with_it.settings["n_findings"] == without.settings["n_findings"] == 2
    assert with_it.settings["evidence_threshold_t"] == without.settings["evidence_threshold_t"]
    c = with_it.candidate("out_of_plane")
    assert c.extra["p"] <= ALPHA_OOP and c.extra["alpha"] == ALPHA_OOP
    assert c.improvement_pct > 5 and c.supported and with_it.candidate("second_mode").supported
    assert without.verdict == "second_mode" and with_it.verdict == "out_of_plane"
    rec = with_it.settings["parsimony"]["beside_own"]
    assert rec["bend"] == "second_mode" and not rec["kept"] and rec["t"] <= rec["threshold_t"]
    assert rec["course_p"] <= ALPHA_OOP and rec["course_r2"] > 0.5  # second_mode's course is the swing's
    assert "also support second_mode" in with_it.explanation and "no longer lowers" in with_it.explanation
    alone = diagnose(Y, effects=["offset", eff], n_folds=8)
    assert alone.verdict == "out_of_plane" and "length" in alone.explanation
    assert "beside_own" not in alone.settings["parsimony"]


def test_a_second_excitation_beside_a_swing_keeps_the_verdict():
    """The other side of the nested check: a second excitation whose course is not the swing's still lowers the
    held-out error beside the out_of_plane term, so it stays the verdict and the swing is reported beside it."""
    Y, channel, z = _swing_and_second(np.random.default_rng(3), second=0.6)
    d = diagnose(Y, effects=["offset", "second_mode", OutOfPlane(channel, z)], n_folds=8)
    assert d.candidate("out_of_plane").supported and d.verdict == "second_mode"
    rec = d.settings["parsimony"]["beside_own"]
    assert rec["kept"] and rec["t"] > rec["threshold_t"] and rec["improvement_over_own_pct"] > 0
    # second_mode's course mixes v with the swing's w (the bends carry both), so the course test alone would rename
    # it: the nested held-out test keeps it
    assert "course_p" in rec
    assert "out_of_plane is supported too" in d.explanation and "still lowers" in d.explanation


@pytest.mark.parametrize("t, rmse, course_p, kept", [
    (3.0, 0.9, 0.001, True),    # adds beside the swing's term: kept, whatever its course
    (1.0, 0.9, 0.001, False),   # adds nothing and its course is the swing's: out_of_plane
    (1.0, 0.9, 0.2, True),      # adds nothing, but its course is not the swing's: kept (a real second excitation)
    (3.0, 1.1, 0.001, False),   # t above the threshold but a higher held-out RMSE: adds nothing
    (1.0, 0.9, None, False),    # no per-frame course to compare: the nested held-out test alone decides
])
def test_weigh_beside_own_needs_both_conditions_to_rename(t, rmse, course_p, kept):
    from types import SimpleNamespace
    from rce_gtsam.diagnosis.verdict import weigh_beside_own
    own = SimpleNamespace(heldout_rmse=1.0, extra={"alpha": ALPHA_OOP})
    nested = {"t": t, "heldout_rmse": rmse, **({} if course_p is None else {"course_p": course_p})}
    assert weigh_beside_own(None, own, nested, t_crit=2.6) is kept
    assert weigh_beside_own(None, own, None, t_crit=2.6)  # the nested fit could not be scored: kept


@pytest.fixture(scope="module")
def swinging():
    """The 3-D simulator at the default out-of-plane strength (share 0.5, branch plane tilted 30 deg)."""
    sim = simulate(SimulationConfig(seed=1, effects=("out_of_plane",), n_nodes=14, n_frames=450))
    return sim, analyze(sim.tracks, sim.graph, preset="default", n_boot=0)


def test_pipeline_names_a_swing_and_not_a_planar_branch_with_slide(swinging):
    _, res = swinging
    d = diagnose_result(res, effects="out_of_plane,offset")
    assert d.verdict == "out_of_plane" and d.candidate("out_of_plane").extra["p"] <= ALPHA_OOP
    planar = simulate(SimulationConfig(seed=1, artifacts=ArtifactConfig(("slide",), 2.0), **SMALL))
    dp = diagnose_result(analyze(planar.tracks, planar.graph, preset="default", n_boot=0),
                         effects="out_of_plane,offset")
    assert dp.verdict != "out_of_plane" and dp.candidate("out_of_plane").extra["p"] > ALPHA_OOP


def test_rce_diagnose_names_out_of_plane_end_to_end(swinging, tmp_path, capsys):
    from rce_gtsam.cli import main
    sim, _ = swinging
    sim.write(tmp_path / "rec")
    js = tmp_path / "d.json"
    assert main(["diagnose", str(tmp_path / "rec" / "tracks.csv"), str(tmp_path / "rec" / "graph.json"),
                 "--effects", "out_of_plane", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert d["verdict"] == "out_of_plane" and d["status"] == "effect"
    c = d["candidates"][0]
    assert c["length_p"] <= ALPHA_OOP and len(c["length_loadings"]) == len(sim.graph.edges)
    assert "out_of_plane" in capsys.readouterr().out


def test_fitting_it_by_name_is_refused_before_any_work(swinging):
    from rce_gtsam.errors import InputError
    sim, _ = swinging
    with pytest.raises(InputError, match="out_of_plane reads more of the recording"):
        analyze(sim.tracks, sim.graph, effects="out_of_plane")


def test_an_inconclusive_budget_quotes_the_length_test():
    """Where the floor is only bounded because segments stretch, the explanation gives the length test's p rather
    than calling out-of-plane motion untestable."""
    from types import SimpleNamespace

    from rce_gtsam.diagnosis.explain import out_of_plane_text

    cand = SimpleNamespace(effect="out_of_plane", extra={"length_p": 0.046, "alpha": 0.01})
    text = out_of_plane_text(SimpleNamespace(candidates=[cand]))
    assert "p = 0.046 against its level 0.01" in text and "share no course" in text
    assert "not tested here" in out_of_plane_text(SimpleNamespace(candidates=[]))


def test_an_own_test_names_nothing_unless_its_held_out_error_falls():
    """The length test alone is a full-data test: a significant p with no held-out gain on the lengths is not
    significant (a planar user-path recording had p 0.007 and -1.9 %)."""
    from rce_gtsam.diagnosis.own_family import own_test_significant

    class Own:
        def __init__(self, gain):
            self.gain = gain

        def own_family_test(self, fit, seed=0):
            return {"p": 0.001, "alpha": ALPHA_OOP, "heldout_gain_pct": self.gain}

    extra = {}
    assert own_test_significant(Own(12.0), None, 0, extra) and extra["heldout_gain_pct"] == 12.0
    assert not own_test_significant(Own(-1.9), None, 0, {})
    assert not own_test_significant(Own(0.0), None, 0, {})
