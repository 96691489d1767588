"""The diagnosis' shape: evidence -> decision -> report with no import cycle among its modules, none of them long,
the report reading result types only, the decision computing no statistic, every test in the common shape.

The import walk counts every import, at module level, inside functions and under ``if TYPE_CHECKING:`` (a
type-only import back still couples two modules: that is how explain, verdict, oracle and io used to lean on
diagnose).
"""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

import numpy as np
import pytest

DIAGNOSIS = Path(__file__).resolve().parents[1] / "rce_gtsam" / "diagnosis"
MAX_LINES = 500


def diagnosis_imports(folder: Path = DIAGNOSIS) -> dict[str, set[str]]:
    """module name (stem) -> the modules of ``folder`` (the diagnosis) it imports anywhere in its file."""
    mods = {p.stem for p in folder.glob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for path in folder.glob("*.py"):
        me = path.stem
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                if node.level == 1:  # from .x import ... / from . import x
                    targets = [node.module] if node.module else [a.name for a in node.names]
                elif node.level == 0 and (node.module or "").startswith("rce_gtsam.diagnosis"):
                    rest = node.module[len("rce_gtsam.diagnosis"):].lstrip(".")
                    targets = [rest.split(".")[0]] if rest else [a.name for a in node.names]
                else:
                    continue
            elif isinstance(node, ast.Import):
                targets = [a.name[len("rce_gtsam.diagnosis."):].split(".")[0] for a in node.names
                           if a.name.startswith("rce_gtsam.diagnosis.")]
            else:
                continue
            graph[me] |= {t for t in targets if t in mods and t != me and t != "__init__"}
    return graph


def test_the_diagnosis_has_no_import_cycle():
    graph = diagnosis_imports()
    assert {"diagnose", "evidence", "decision", "result", "explain"} <= set(graph)
    try:
        order = tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        pytest.fail(f"import cycle in rce_gtsam/diagnosis: {' -> '.join(exc.args[1])}")
    assert order.index("result") < order.index("decision") < order.index("diagnose")


def test_the_walk_sees_a_cycle_when_there_is_one(tmp_path):
    """The test above would catch a cycle: the same walk on two modules that import each other (one lazily)."""
    (tmp_path / "a.py").write_text("from .b import x\n")
    (tmp_path / "b.py").write_text("def f():\n    from .a import y\n")
    graph = diagnosis_imports(tmp_path)
    assert graph == {"a": {"b"}, "b": {"a"}}
    with pytest.raises(graphlib.CycleError):
        tuple(graphlib.TopologicalSorter(graph).static_order())


def test_no_diagnosis_module_is_long():
    long = {p.name: n for p in DIAGNOSIS.glob("*.py") if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_evidence_decision_report_depend_one_way():
    """The report reads result types only; the decision reads results, never the tests' machinery; nothing the
    results need imports the diagnosis' driver."""
    graph = diagnosis_imports()
    assert graph["explain"] == {"result"}
    assert graph["decision"] <= {"result", "verdict"} and graph["verdict"] <= {"result", "heldout"}
    assert not {m for m, deps in graph.items() if "diagnose" in deps} - {"io"}
    assert "decision" not in graph["evidence"] and "explain" not in graph["evidence"]
    assert len((DIAGNOSIS / "decision.py").read_text().splitlines()) < 200
    assert len((DIAGNOSIS / "diagnose.py").read_text().splitlines()) < 300


def test_every_test_reports_in_the_common_shape():
    """A real diagnosis (delay in the simulator's matrices): each candidate carries its tests as TestResults, each
    with a null sentence and a calibration record, and the decision's significance agrees with them."""
    from rce_gtsam.diagnosis.decision import drift_rescued, is_significant
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.diagnosis.result import TestResult
    from _effect_data import synth

    Y, s, *_ = synth("delay", seed=0)
    d = diagnose(Y, root_distance=s, effects=["delay", "offset"], seed=0)
    for c in d.candidates:
        assert {"fold_t", "implausibility", "maxt"} <= set(c.tests), c.tests.keys()
        for name, t in c.tests.items():
            assert isinstance(t, TestResult) and t.name == name
            assert t.null and t.calibration and np.isfinite(t.threshold)
        fold, score = c.tests["fold_t"], c.tests.get("score")
        assert fold.statistic == c.evidence and c.tests["maxt"].p == c.extra["maxt_p"]
        sig = is_significant(fold.statistic, fold.threshold, None if score is None else score.p,
                             d.settings["score_threshold_p"],
                             c.extra["support_threshold_t"] if score is not None else -np.inf)
        if "heldout_null" in c.tests:
            sig = drift_rescued(c.tests)
        assert sig == c.extra["significant"]
        # the route the report quotes is the decision's, recorded beside it
        route = c.extra["significant_by"]
        if not sig:
            assert route is None
        else:
            assert route == ("held-out" if fold.statistic > fold.threshold else "full-data"), (c.effect, route)
    assert d.report() and "[[Candidates]]" in d.report() and d.explanation in d.report()
