"""The package's import graph: no cycles, and no ``_private`` name imported from another module.

Walks every module's ``import`` / ``from ... import`` statements with :mod:`ast` (function-level imports
included: a lazy import still couples two modules), resolves them to modules of the package and checks the
graph with :func:`graphlib.TopologicalSorter`, which raises :class:`graphlib.CycleError` naming a cycle.
Imports under ``if TYPE_CHECKING:`` are skipped (they never run).
"""

from __future__ import annotations

import ast
import graphlib
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "rce_gtsam"


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _runtime_nodes(tree: ast.AST):
    """Every node except the bodies of ``if TYPE_CHECKING:`` blocks."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            stack.extend(node.orelse)
            continue
        yield node
        stack.extend(ast.iter_child_nodes(node))


def import_graph() -> tuple[dict[str, set[str]], list[str]]:
    """(module -> package modules it imports, ["module imports _name from other"] violations)."""
    mods = _modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    private = []
    for mod, path in mods.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in _runtime_nodes(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                graph[mod] |= {a.name for a in node.names if a.name in mods}
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target not in mods:
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in mods:
                        graph[mod].add(sub)
                        continue
                    graph[mod].add(target)
                    name = alias.name
                    if name.startswith("_") and not (name.startswith("__") and name.endswith("__")):
                        private.append(f"{mod} imports {name} from {target}")
        graph[mod].discard(mod)
    return graph, private


def test_no_private_name_is_imported_across_modules():
    _, private = import_graph()
    assert not private, "\n".join(private)


def test_import_graph_has_no_cycle():
    graph, _ = import_graph()
    assert len(graph) > 40 and "rce_gtsam.model.steps" in graph["rce_gtsam.effects.delay"]
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        pytest.fail(f"import cycle: {' -> '.join(exc.args[1])}")


def test_model_engine_does_not_depend_on_effects_or_diagnosis():
    """Effects plug into the engine; the engine never reaches back into them or into the diagnosis."""
    graph, _ = import_graph()
    for mod in (m for m in graph if m.startswith("rce_gtsam.model")):
        bad = {d for d in graph[mod] if d.startswith(("rce_gtsam.effects", "rce_gtsam.diagnosis.diagnose", "rce_gtsam.diagnosis"))}
        assert not bad, f"{mod} imports {bad}"


def test_effects_import_first_in_a_fresh_interpreter():
    """An effect module imported before anything else (the entry point of the old model <-> effects cycle)."""
    code = "import rce_gtsam.effects.delay, rce_gtsam.model, rce_gtsam.diagnosis.diagnose, rce_gtsam.pipeline"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_the_diagnosis_machinery_names_no_effect():
    """A new effect is one file and a registry line: no module of rce_gtsam/diagnosis/ special-cases an effect by
    its name (a string literal equal to a registered effect's name)."""
    from rce_gtsam import effects

    names = set(effects.names())
    hits = []
    for path in sorted((PACKAGE / "diagnosis").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Constant) and node.value in names:
                hits.append(f"{path.name}:{node.lineno} {node.value!r}")
    assert not hits, hits


def test_help_of_analyze_shows_its_real_signature_and_docstring():
    """``help(rce_gtsam.analyze)`` shows the parameters and the docstring, not ``(*args, **kwargs)``."""
    import inspect
    import pydoc

    import rce_gtsam
    from rce_gtsam.pipeline import analyze
    assert rce_gtsam.analyze is analyze
    params = inspect.signature(rce_gtsam.analyze).parameters
    assert list(params)[:3] == ["tracks", "graph", "preset"] and "effects" in params
    text = pydoc.render_doc(rce_gtsam.analyze, renderer=pydoc.plaintext)
    assert "*args" not in text and "Run the whole analysis on saved tracks" in text
