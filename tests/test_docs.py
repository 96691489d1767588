"""The documentation site builds, its code runs, and it looks right in a browser.

* ``mkdocs build --strict`` (warnings are errors) runs once, on a copy of ``mkdocs.yml``, ``docs/`` and the
  build's hooks in a temporary folder outside the repository: the build executes the tutorial notebooks
  (mkdocs-jupyter, ``execute: true``) there, so this is also the test that they run from any folder, and it
  runs the ``rce`` commands whose output and figures the pages show (``tools/docs_hooks.py``);
* every ```python block of a page runs (a page's blocks in order, as one script) and every ```bash block
  marked ``<!-- runnable -->`` runs its ``rce`` lines, in a scratch folder holding the repository's ``data/``;
* the notebooks import no private name and no test code;
* Debian's chromium takes headless screenshots of the built home page and of "Reading your results"
  (saved where the test prints; ``RCE_DOCS_SCREENSHOT_DIR`` keeps them).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
PAGES = sorted(DOCS.glob("*.md"))
NOTEBOOKS = sorted((DOCS / "notebooks").glob("*.ipynb"))
FENCE = re.compile(r"^(<!-- runnable -->\n)?```(\w*)[^\n]*\n(.*?)^```", re.S | re.M)


def blocks(page: Path, lang: str, runnable_only: bool = False) -> list[str]:
    return [code for mark, kind, code in FENCE.findall(page.read_text())
            if kind == lang and (mark or not runnable_only)]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built with --strict from a copy outside the repository; returns the site folder."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocs_jupyter")
    pytest.importorskip("mkdocstrings")
    work = Path(tempfile.mkdtemp(prefix="rce_docs_test_"))
    shutil.copy(REPO / "mkdocs.yml", work)
    shutil.copytree(DOCS, work / "docs")
    (work / "tools").mkdir()
    shutil.copy(REPO / "tools" / "docs_hooks.py", work / "tools")
    (work / "benchmarks").mkdir()
    shutil.copy(REPO / "benchmarks" / "record.py", work / "benchmarks")
    (work / "data").symlink_to(REPO / "data")
    env = dict(os.environ, OMP_NUM_THREADS="1", NO_MKDOCS_2_WARNING="1",
               PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    p = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(work / "site")],
                       cwd=work, env=env, capture_output=True, text=True)
    assert p.returncode == 0, f"mkdocs build --strict failed:\n{p.stdout[-3000:]}\n{p.stderr[-6000:]}"
    yield work / "site"
    shutil.rmtree(work, ignore_errors=True)


@pytest.mark.slow
def test_site_builds_strict_with_every_page_and_generated_content(site):
    for name in ("index", "getting-started", "own-video", "results", "how-it-works", "diagnosis", "own-effect",
                 "validation", "cli", "api", "limits", "changelog"):
        assert (site / f"{name}.html").is_file(), name
    results = (site / "results.html").read_text()
    assert "<!-- output:" not in results and "rce analyze data/sample_delay" in results
    # the extended kappa rce run writes after a verdict, generated on sample_delay (the diagnosis names delay)
    assert "<!-- kappa-to-report -->" not in results and "Read together: the diagnosis names delay" in results
    assert "<code>kappa_delay</code> [95 % CI]" in results and "<code>kappa_delay_quality</code>" in results
    assert (site / "img" / "review.png").is_file() and "img/review.png" in (site / "own-video.html").read_text()
    for fig in ("compliance", "kappa_overlay", "residuals", "heldout_error", "variance_budget", "residual_analysis",
                "effect_before_after", "smoothing", "motion", "excitation", "bending_fit", "uncertainty_overlay",
                "residuals_diagnosis", "kappa_to_report", "kappa_to_report_overlay"):
        assert f"generated/analysis/{fig}.png" in results and (site / "generated" / "analysis" / f"{fig}.png").is_file()
    for effect in ("delay", "dynamics", "second_mode", "offset", "nonlinear"):
        assert (site / "generated" / "signatures" / f"{effect}.png").is_file()
    cli = (site / "cli.html").read_text()
    assert all(f"rce {c}" in cli for c in ("analyze", "diagnose", "track", "annotate", "simulate", "run", "view",
                                           "batch"))
    validation = (site / "validation.html").read_text()
    assert "<!-- validation-records -->" not in validation and "bench_quality.py" in validation
    api = (site / "api.html").read_text()
    assert "rce_gtsam.pipeline.analyze" in api and "ResponseModel" in api


@pytest.mark.slow
def test_site_fetches_nothing_from_outside(site):
    """No script, stylesheet or font from another host: the site works offline (theme.font: false)."""
    external = re.compile(r'<(?:script|link|img)[^>]+(?:src|href)="(?:https?:)?//[^"]+"')
    for page in site.rglob("*.html"):
        text = page.read_text()
        assert not external.findall(text), f"{page.name}: {external.findall(text)[:3]}"
        assert "fonts.googleapis" not in text and "cdnjs" not in text, page.name


@pytest.mark.slow
def test_notebooks_ran_in_the_build_and_show_their_outputs(site):
    """The build executed the notebooks (outside the repository): their pages hold figures and no error."""
    for nb in NOTEBOOKS:
        page = (site / "notebooks" / f"{nb.stem}.html").read_text()
        assert "data:image/png;base64" in page, f"{nb.name}: no figure in the built page"
        # allow_errors: false already fails the build on an error; a stray traceback in an output would show here
        assert "Traceback (most recent call last)" not in page and "CellExecutionError" not in page, nb.name


def test_notebooks_use_the_public_api_only():
    assert NOTEBOOKS
    for nb in NOTEBOOKS:
        code = "\n".join("".join(c["source"]) for c in json.loads(nb.read_text())["cells"] if c["cell_type"] == "code")
        assert "sys.path" not in code and "tests" not in code, nb.name
        private = re.findall(r"(?:import|from)\s+[\w.]*\b_\w+|import[^\n]*\b_\w+|\.\s*_[a-z]\w*\(", code)
        assert not private, f"{nb.name}: private names {private}"
        assert "moving-block" not in "".join(
            "".join(c["source"]) for c in json.loads(nb.read_text())["cells"]).replace(
            "`paper` preset resamples moving blocks", ""), f"{nb.name}: the default CIs are not a moving-block bootstrap"


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    ws = tmp_path_factory.mktemp("docs_code")
    (ws / "data").symlink_to(REPO / "data")
    return ws


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in PAGES if blocks(p, "python")], ids=lambda p: p.stem)
def test_python_blocks_of_a_page_run(page, scratch):
    code = "\n".join(blocks(page, "python"))
    env = dict(os.environ, OMP_NUM_THREADS="1", MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, "-c", code], cwd=scratch, env=env, capture_output=True, text=True)
    assert p.returncode == 0, f"{page.name}:\n{p.stderr[-3000:]}"


@pytest.mark.slow
def test_runnable_shell_blocks_run(scratch):
    cmds = [line.strip() for page in PAGES for block in blocks(page, "bash", runnable_only=True)
            for line in block.splitlines() if line.strip().startswith("rce ")]
    assert len(cmds) >= 2
    for cmd in cmds:
        args = shlex.split(cmd.split(" #")[0])[1:]
        p = subprocess.run([sys.executable, "-m", "rce_gtsam.cli", *args], cwd=scratch, capture_output=True,
                           text=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
        assert p.returncode == 0, f"docs command failed: {cmd}\n{p.stderr[-2000:]}"


def test_every_page_is_in_the_nav_and_links_resolve_in_the_readme():
    nav = (REPO / "mkdocs.yml").read_text()
    for page in PAGES:
        assert page.name in nav, f"{page.name} is not in mkdocs.yml's nav"
    readme = (REPO / "README.md").read_text()
    for target in re.findall(r"\]\((docs/[^)#]+)", readme):
        assert (REPO / target).exists(), f"README links to missing {target}"


def test_validation_records_follow_the_schema():
    sys.path.insert(0, str(REPO / "benchmarks"))
    try:
        from record import load_records, save_record, validate_record
    finally:
        sys.path.pop(0)
    records = load_records(DOCS / "validation")
    assert records, "no validation record"
    for _, rec in records:
        assert rec["command"].startswith("python benchmarks/")
    with tempfile.TemporaryDirectory() as tmp:
        path = save_record("x", title="t", command="python benchmarks/x.py", columns=["a (px)"], rows=[[1.5]],
                           directory=tmp)
        assert json.loads(path.read_text())["rows"] == [[1.5]]
    with pytest.raises(ValueError, match="row 0"):
        validate_record({**rec, "rows": [[1] * (len(rec["columns"]) + 1)]})


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.slow
@pytest.mark.parametrize("page", ["index", "results"])
def test_screenshot_in_chromium(site, page, tmp_path, capsys):
    chromium = _chromium()
    if not chromium:
        pytest.skip("needs Debian's chromium (`make test` installs it as root)")
    out_dir = Path(os.environ.get("RCE_DOCS_SCREENSHOT_DIR") or tmp_path)
    out_dir.mkdir(parents=True, exist_ok=True)
    shot = out_dir / f"docs_{page}.png"
    profile = tempfile.mkdtemp(prefix="rce_chromium_")
    try:
        p = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                            "--disable-component-update", "--disable-sync", "--no-first-run",
                            f"--user-data-dir={profile}", f"--screenshot={shot}", "--window-size=1280,1600",
                            "--hide-scrollbars", "--force-device-scale-factor=1", (site / f"{page}.html").as_uri()],
                           capture_output=True, text=True, timeout=120)
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    assert p.returncode == 0 and shot.is_file(), p.stderr[-2000:]
    with capsys.disabled():  # the path is printed even when pytest captures output: look at the picture
        print(f"\nscreenshot of {page}.html: {shot}")
    import numpy as np
    from matplotlib.image import imread
    img = imread(shot)
    assert img.shape[:2] == (1600, 1280)
    # a rendered page, not a blank one: Material's header colour and the page's text both present
    assert np.unique((img[..., :3] * 255).astype(np.uint8).reshape(-1, 3), axis=0).shape[0] > 50


def test_the_settings_the_pages_quote_are_the_code_s():
    """The pages quote a few settings (not measurements: those come from docs/validation/); they must be the code's."""
    from rce_gtsam import get_preset
    from rce_gtsam.diagnosis.settings import N_FOLDS, RESOLUTION
    from rce_gtsam.sim.simulate import NoiseConfig

    text = "\n".join(p.read_text() for p in PAGES)
    default, paper = get_preset("default"), get_preset("paper")
    assert N_FOLDS == 16 and "cut into 16 blocks" in text and "16 held-out folds" in text
    assert RESOLUTION == 1e-3 and "at least 0.1 % of the bending variance" in text
    assert default.smoother.window_frames == 1200 and "longer than 1200 frames" in text
    assert paper.compliance.block_length == 25 and "moving blocks of 25 frames" in text
    assert paper.compliance.n_boot == 250 and "25 frames, 250 resamples" in text
    assert paper.compliance.prior_strength == 12 and "(λ = 12)" in text
    assert paper.smoother.presmooth_window == 5 and "5-frame moving average" in text
    assert default.smoother.presmooth_window == 1 and default.smoother.edge_weight == 0
    assert default.bending.rest == "median" and paper.bending.rest == "first"
    assert NoiseConfig().sigma_across_px == 0.25 and "0.25 px" in text


def test_the_quality_flags_and_plausibility_rules_the_pages_describe_are_the_code_s():
    """Every quality reason has a row in results.md's flags table, with the code's cutoffs; the diagnosis page's
    plausibility limits are plausibility.py's."""
    from rce_gtsam import quality
    from rce_gtsam.diagnosis import plausibility

    results = (DOCS / "results.md").read_text()
    table = results[results.index("| flag | meaning | what to do |"):]
    table = table[:table.index("\n\n")]
    flags = re.findall(r"^\| `(\w+)` \|", table, re.M)
    assert flags == list(quality.REASONS), flags
    assert (round(quality.STIFF_BELOW, 2), round(quality.COMPLIANT_ABOVE, 2)) == (0.71, 1.41)
    assert "below 2^−½ = 0.71 **and** above 2^½ = 1.41" in table
    assert quality.CALM_SHARE == 0.5 and "`z_var_seen` below 0.5" in table
    assert quality.POOR_FIT_SHARE == 0.5 and "0.5 × (1 − 1/SNR)" in table
    assert quality.LOST_SHARE == 0.5 and "more than half of the frames" in table
    diagnosis = (DOCS / "diagnosis.md").read_text()
    assert plausibility.SATURATION_REACH == 2.0 and "beyond twice the largest\n   deflection seen" in diagnosis
    assert plausibility.SHORTEST_PERIOD_FRAMES == 4.0 and "under 4 frames" in diagnosis
    assert plausibility.SHORTEST_LAG_FRAMES == 1.0 and "shorter than one frame" in diagnosis
    assert "the held-out frames need only agree in sign (fold t > 0)" in diagnosis.replace("\n   ", " ")
    assert "`no (implausible fit)`" in diagnosis
    from rce_gtsam import effects
    named_by_both = [n for n, c in effects.CANDIDATES.items() if c.needs_both_tests]
    assert named_by_both == ["nonlinear"] and "is named only where **both** its\ntests pass" in diagnosis
