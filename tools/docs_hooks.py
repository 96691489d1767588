"""MkDocs hooks (``mkdocs.yml``: ``hooks:``): everything the pages show that a program measures is made here,
at build time, by the project's own code, so no number or figure in the docs is typed by hand.

Markers a page may hold (each on a line of its own):

* ``<!-- cli-reference -->`` — the help of ``rce`` and of every sub-command, from
  :func:`rce_gtsam.cli.app.build_parser`;
* ``<!-- validation-records -->`` — one section per record in ``docs/validation/*.json`` (schema:
  ``benchmarks/record.py``): title, table, the command that re-measures it, its date;
* ``<!-- validation-record: NAME -->`` — the table of the one record ``docs/validation/NAME.json``, with its
  date and command (no heading);
* ``<!-- output: NAME -->`` — what step NAME of :data:`STEPS` printed (an ``rce`` command run on the data the
  repository ships, in a scratch folder);
* ``<!-- kappa-to-report -->`` — the κ columns ``rce run`` writes after a verdict and its "Read together:" line,
  for the analysis and diagnosis of :data:`STEPS` (:func:`kappa_to_report_example`).

Files the steps write under ``figures/`` are added to the site as ``generated/<step>/<file>``, and the effect
signatures (:func:`signature_figures`) as ``generated/signatures/<effect>.png``.
"""

from __future__ import annotations

import argparse
import html
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from mkdocs.structure.files import File

#: (name, rce arguments) run in order in the scratch folder; ``data/`` there is the repository's data.
STEPS = (
    ("analysis", "analyze data/sample_delay/tracks.csv data/sample_delay/graph.json --out out/analysis --quiet"),
    ("diagnosis", "diagnose data/sample_delay/tracks.csv data/sample_delay/graph.json --json out/diagnosis.json "
                  "--candidates delay,offset,second_mode --figures out/analysis/figures --quiet"),
)
#: effects shown by their signature, in the order of the diagnosis page
SIGNATURE_EFFECTS = ("delay", "dynamics", "second_mode", "offset", "nonlinear")

_state: dict = {}


def _data_dir(config) -> Path:
    """The repository's ``data/``: beside mkdocs.yml, else beside the installed package (editable install)."""
    here = Path(config.config_file_path).parent / "data"
    if here.is_dir():
        return here
    import rce_gtsam
    return Path(rce_gtsam.__file__).resolve().parents[1] / "data"


def _run_steps(config, work: Path) -> dict[str, str]:
    (work / "data").symlink_to(_data_dir(config))
    env = dict(os.environ, OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"))
    outputs = {}
    for name, args in STEPS:
        p = subprocess.run([sys.executable, "-m", "rce_gtsam.cli", *args.split()], cwd=work, env=env,
                           capture_output=True, text=True)
        if p.returncode != 0:
            raise RuntimeError(f"docs step {name!r} (rce {args}) failed:\n{p.stderr[-3000:]}")
        outputs[name] = f"$ rce {args}\n{p.stdout}{p.stderr}".rstrip()
    return outputs


def signature_figures(out_dir: Path, n_nodes: int = 14, n_frames: int = 600, seed: int = 0) -> dict[str, Path]:
    """One PNG per simulated effect: the residuals the rank-1 model leaves on noise-free bending.

    Each effect is simulated alone at the simulator's default strength (:mod:`rce_gtsam.sim.simulate`,
    ``n_nodes`` nodes, ``n_frames`` frames, no tracking noise), its true bend response (degrees) is fitted
    by the default preset's rank-1 model (:func:`rce_gtsam.model.compliance.fit_rank1`) and the residual
    observed - kappa z is drawn as a heatmap (:func:`rce_gtsam.viz.figures.fig_residual_heatmap`)."""
    import numpy as np

    from rce_gtsam import get_preset
    from rce_gtsam.model.compliance import fit_rank1
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate
    from rce_gtsam.viz.figures import fig_residual_heatmap
    from rce_gtsam.viz.style import save_png

    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = get_preset("default").compliance
    written = {}
    for effect in SIGNATURE_EFFECTS:
        sim = simulate(SimulationConfig(n_nodes=n_nodes, n_frames=n_frames, effects=(effect,), seed=seed,
                                        noise=NoiseConfig(enabled=False)))
        Y = sim.response_true
        R = Y - fit_rank1(Y, cfg).predict()
        edges = list(sim.kappa_true)
        fig = fig_residual_heatmap(R, np.arange(Y.shape[1]), [f"{j}→{c}" for j, c in edges],
                                   f"{effect}: what the rank-1 model leaves (noise-free, deg)")
        written[effect] = save_png(fig, out_dir / f"{effect}.png")
    return written


def kappa_to_report_example(data: Path, candidates: str = "delay,offset,second_mode", n_rows: int = 6,
                            figure_dir: Path | None = None) -> str:
    """What ``rce run`` adds after a verdict, on ``data/sample_delay`` analysed and diagnosed as :data:`STEPS` do
    (the same candidates and seed): a table of the first ``n_rows`` segments with the rank-1 ``kappa`` beside
    ``kappa_<effect>`` and the ``report`` column of compliance_summary.csv (:func:`rce_gtsam.kappa_report.add_to_summary`),
    and the printed "Read together:" line (:func:`rce_gtsam.cli.run.read_together`). Markdown. With ``figure_dir``,
    also ``kappa_to_report.png`` there, as ``rce run`` draws it (:func:`rce_gtsam.viz.figures.fig_kappa_to_report`)."""
    import dataclasses
    import textwrap

    from rce_gtsam import analyze
    from rce_gtsam.cli.run import read_together
    from rce_gtsam.diagnosis.io import diagnose_result
    from rce_gtsam.kappa_report import kappa_after_verdict

    result = analyze(data / "sample_delay" / "tracks.csv", data / "sample_delay" / "graph.json")
    diagnosis = diagnose_result(result, effects=candidates, seed=0)
    result = dataclasses.replace(result, kappa_choice=kappa_after_verdict(result, diagnosis))
    if figure_dir is not None:
        from rce_gtsam.viz.figures import fig_kappa_to_report
        from rce_gtsam.viz.overlays import REPORTED_OVERLAY, write_overlays
        from rce_gtsam.viz.style import save_png
        figure_dir.mkdir(parents=True, exist_ok=True)
        save_png(fig_kappa_to_report(result), figure_dir / "kappa_to_report.png")
        write_overlays(result, figure_dir, names=[REPORTED_OVERLAY])
    col = result.kappa_choice.column
    df = result.summary().dropna(subset=["kappa"]).head(n_rows)
    ci = lambda lo, hi: f"[{lo:.2f}, {hi:.2f}]"  # noqa: E731
    extended = [] if col == "kappa" else [f"`{col}` [95 % CI]", f"`{col}_quality`"]
    head = ["segment", "`kappa` [95 % CI]", "`quality`", *extended, "`report`"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in df.to_dict("records"):
        cells = [f"{r['parent']}→{r['child']}", f"{r['kappa']:.3f} {ci(r['kappa_ci_low'], r['kappa_ci_high'])}",
                 _cell(r["quality"])]
        if col != "kappa":
            cells += [f"{r[col]:.3f} {ci(r[col + '_ci_low'], r[col + '_ci_high'])}", _cell(r[col + "_quality"])]
        cells.append(_cell(r["report"]))
        rows.append("| " + " | ".join(cells) + " |")
    line = textwrap.fill(read_together(result, diagnosis), 100)
    return "\n".join([*rows, "", f"(the first {len(df)} segments)", "", "```text", line, "```"])


def _cli_reference() -> str:
    from rce_gtsam.cli.app import build_parser

    parser = build_parser()
    parts = ["## rce", "", "```text", parser.format_help().rstrip(), "```", ""]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sub.choices.items():
        parts += [f"## rce {name}", "", "```text", p.format_help().rstrip(), "```", ""]
    return "\n".join(parts)


def _cell(v) -> str:
    return html.escape(str(v)).replace("|", "&#124;")


def _records(config) -> list[tuple[str, dict]]:
    sys.path.insert(0, str(Path(config.config_file_path).parent / "benchmarks"))
    try:
        from record import load_records
    finally:
        sys.path.pop(0)
    return load_records(Path(config.docs_dir) / "validation")


def _validation_records(config, only: str | None = None) -> str:
    parts = []
    for stem, rec in _records(config):
        if only is not None and stem != only:
            continue
        if only is None:
            parts += [f"## {rec['title']}", "", rec["description"], ""]
        parts += ["| " + " | ".join(_cell(c) for c in rec["columns"]) + " |",
                  "|" + "---|" * len(rec["columns"])]
        parts += ["| " + " | ".join(_cell(v) for v in row) + " |" for row in rec["rows"]]
        parts += [""] + [f"* {_cell(n)}" for n in rec.get("notes", [])]
        parts += ["", f"Measured on {rec['date']} (`docs/validation/{stem}.json`); re-measure with:", "",
                  "```bash", rec["command"], "```", ""]
    if only is not None and not parts:
        raise RuntimeError(f"no validation record docs/validation/{only}.json")
    return "\n".join(parts) if parts else "No records yet."


def on_config(config):
    _state.clear()
    _state["work"] = Path(tempfile.mkdtemp(prefix="rce_docs_"))
    return config


def on_files(files, config):
    work = _state["work"]
    _state["outputs"] = _run_steps(config, work)
    _state["kappa_to_report"] = kappa_to_report_example(work / "data", figure_dir=work / "out" / "analysis" / "figures")
    signature_figures(work / "signatures")
    generated = {f"generated/{name}/{p.name}": p for name in ("analysis",)
                 for p in sorted((work / "out" / name / "figures").glob("*.png"))}
    generated.update({f"generated/signatures/{p.name}": p for p in sorted((work / "signatures").glob("*.png"))})
    for uri, path in generated.items():
        files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files


def on_page_markdown(markdown, page, config, files):
    if "<!-- cli-reference -->" in markdown:
        markdown = markdown.replace("<!-- cli-reference -->", _cli_reference())
    if "<!-- validation-records -->" in markdown:
        markdown = markdown.replace("<!-- validation-records -->", _validation_records(config))
    for name in re.findall(r"<!-- validation-record: ([\w-]+) -->", markdown):
        markdown = markdown.replace(f"<!-- validation-record: {name} -->", _validation_records(config, only=name))
    if "<!-- kappa-to-report -->" in markdown:
        markdown = markdown.replace("<!-- kappa-to-report -->", _state["kappa_to_report"])
    for name, text in _state.get("outputs", {}).items():
        marker = f"<!-- output: {name} -->"
        if marker in markdown:
            markdown = markdown.replace(marker, f"```text\n{text}\n```")
    return markdown


_EXTERNAL_SCRIPTS = (
    # nbconvert's templates: an empty MathJax <script src=""> (the notebooks hold no maths) and a module that
    # would import mermaid from a CDN when a notebook holds a diagram (ours hold none); the site fetches nothing
    re.compile(r'<script src="">\s*</script>'),
    re.compile(r'<script type="module">(?:(?!</script>).)*?cdnjs\.cloudflare\.com(?:(?!</script>).)*</script>', re.S),
)


#: Sphinx cross-reference roles in the docstrings (``:func:`name```) as mkdocstrings renders them: the role
#: before the code span, and a leading ``~`` inside it
_ROLE = re.compile(r":(?:func|mod|class|meth|data|attr|exc|obj):(<code>)~?")


def on_post_page(output, page, config):
    for pattern in _EXTERNAL_SCRIPTS:
        output = pattern.sub("", output)
    return _ROLE.sub(r"\1", output)


def on_post_build(config):
    shutil.rmtree(_state.get("work", ""), ignore_errors=True)
