"""One recording of a batch, as a Dask task: track (video rows) -> analyze -> diagnose -> ``OUT/<id>/``.

The stages are the library functions ``rce run`` / ``rce analyze`` + ``rce diagnose`` call
(:func:`rce_gtsam.pipeline.analyze`, :func:`rce_gtsam.diagnosis.io.diagnose_result`, the tracker of
:func:`rce_gtsam.track.make_tracker`, the figure writers of ``rce analyze``), so a recording's files are
those the single-recording commands write with the same inputs and options.

Every task ends by writing ``OUT/<id>/batch_record.json`` (:data:`RECORD_NAME`): the input fingerprint,
``status`` ("ok" or "failed"), the error (one line) and its kind ("input": the input files are bad, so an
unchanged re-run would fail again; "error": anything else, retried on a re-run), the files written and
the wall time. A failure never raises out of the task, so one bad recording does not stop the others.
"""

from __future__ import annotations

import json
import os
import socket
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from types import SimpleNamespace

from ..errors import InputError
from .manifest import Recording
from .options import BatchOptions

RECORD_NAME = "batch_record.json"


@dataclass(frozen=True)
class Outcome:
    """What happened to one recording. status: "ok" (computed), "skipped" (outputs up to date), "failed".
    error: one line (None unless failed); error_kind: "input" | "error" | None. elapsed_s: wall seconds of
    the computation (of the stored run when skipped). worker: "host:pid" that ran it (None when skipped)."""

    id: str
    status: str
    fingerprint: str
    error: str | None = None
    error_kind: str | None = None
    elapsed_s: float = 0.0
    worker: str | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def read_record(folder: Path) -> dict | None:
    """The stored ``batch_record.json`` of a recording folder, or None when absent or unreadable."""
    try:
        return json.loads((Path(folder) / RECORD_NAME).read_text())
    except (OSError, ValueError):
        return None


def stored_outcome(folder: Path, fp_hash: str) -> Outcome | None:
    """The outcome a re-run can reuse: outputs complete (every recorded file present) with the same input
    fingerprint, or a failure caused by these very inputs (``error_kind == "input"``). Else None."""
    rec = read_record(folder)
    if not rec or rec.get("fingerprint") != fp_hash:
        return None
    if rec.get("status") == "ok" and rec.get("files") and all((Path(folder) / f).is_file() for f in rec["files"]):
        return Outcome(id=rec["id"], status="skipped", fingerprint=fp_hash, elapsed_s=rec.get("elapsed_s", 0.0))
    if rec.get("status") == "failed" and rec.get("error_kind") == "input":
        return Outcome(id=rec["id"], status="failed", fingerprint=fp_hash, error=rec.get("error"),
                       error_kind="input", elapsed_s=rec.get("elapsed_s", 0.0))
    return None


def process_recording(recording: Recording, out_root: str | Path, options: BatchOptions, fp_hash: str) -> Outcome:
    """Run one recording into ``out_root/<id>/`` and record the outcome there; never raises on a bad
    recording (the error is returned and stored)."""
    folder = Path(out_root) / recording.id
    worker = f"{socket.gethostname()}:{os.getpid()}"
    t0 = time.perf_counter()
    try:
        files = run_pipeline(recording, options, folder)
        outcome = Outcome(id=recording.id, status="ok", fingerprint=fp_hash,
                          elapsed_s=time.perf_counter() - t0, worker=worker)
    except Exception as exc:  # noqa: BLE001 - a failed recording is a result, not a crash of the batch
        kind = "input" if isinstance(exc, InputError) else "error"
        msg = str(exc) if kind == "input" else f"{type(exc).__name__}: {exc}"
        outcome = Outcome(id=recording.id, status="failed", fingerprint=fp_hash,
                          error=" ".join(msg.split()) or type(exc).__name__, error_kind=kind,
                          elapsed_s=time.perf_counter() - t0, worker=worker)
        files = []
    write_record(folder, recording, outcome, files)
    return outcome


def write_record(folder: Path, recording: Recording, outcome: Outcome, files) -> None:
    """Write ``batch_record.json`` (atomically) for ``outcome``."""
    from ..diagnosis.io import write_json_atomic
    write_json_atomic({**outcome.as_dict(), "kind": recording.kind, "row": recording.row,
                       "inputs": {k: str(v) for k, v in recording.input_files.items()},
                       "files": sorted(str(f) for f in files)}, Path(folder) / RECORD_NAME)


def run_pipeline(recording: Recording, options: BatchOptions, folder: Path) -> list[str]:
    """Track (video rows), analyze and diagnose one recording; write its folder like ``rce run`` does.
    Returns the written file names (relative to ``folder``)."""
    import dataclasses

    from ..cli.analyze import extra_writers
    from ..cli.wording import cli_wording_json
    from ..diagnosis.io import diagnose_result, diagnosis_for_viz, diagnosis_json
    from ..kappa_report import kappa_after_verdict
    from ..pipeline import analyze

    preset = options.preset_for(recording)
    table = None
    if recording.kind == "video":
        import tempfile

        from ..tracks import load_tracks, write_table_atomic
        table, graph, t_track = _track(recording, options)
        # analyse the tracks exactly as `rce run` does: from the CSV as written (full precision)
        with tempfile.TemporaryDirectory(prefix="rce_batch_") as scratch:
            csv = Path(scratch) / "tracks.csv"
            write_table_atomic(table, csv)
            tracks = load_tracks(csv, graph)
        result = analyze(tracks, graph, preset=preset, seed=options.seed, n_boot=options.n_boot)
        result.timings_s["track"] = t_track
        result.inputs.update(video=str(recording.video), annotations=str(recording.annotations),
                             graph=str(recording.graph), tracks=str(folder / "tracks.csv"))
    else:
        result = analyze(recording.tracks, recording.graph, preset=preset, seed=options.seed,
                         n_boot=options.n_boot)
    diagnosis = diagnose_result(result, effects=options.effects, seed=options.seed or 0)
    # the kappa to report after the verdict, beside the rank-1 kappa, as `rce run` writes it
    result = dataclasses.replace(result, kappa_choice=kappa_after_verdict(result, diagnosis))
    # a command-line tool: the advice in command-line words, as `rce run` writes it (the named effect's kappa is
    # already in compliance_summary.csv, kappa_<effect>: no second command to run)
    written = result.kappa_choice.column if result.kappa_choice.fitted else None
    view = cli_wording_json(diagnosis_for_viz(diagnosis, result), written) if options.figures else None

    def write_inputs_and_diagnosis(_result, tmp: Path) -> dict:
        if table is not None:
            table.to_csv(tmp / "tracks.csv", index=False)
        (tmp / "diagnosis.json").write_text(
            json.dumps(cli_wording_json(diagnosis_json(diagnosis, result), written), indent=1) + "\n")
        return {}

    written = result.write(folder, extra_writers=[write_inputs_and_diagnosis, *extra_writers(
        SimpleNamespace(no_figures=not options.figures), video=recording.video, diagnosis=view)])
    return sorted(written)


def _track(recording: Recording, options: BatchOptions):
    """Track a video row: (tracks table, graph, seconds)."""
    from ..graph import load_graph
    from ..track import load_annotations, make_tracker, open_video

    t0 = time.perf_counter()
    graph = load_graph(recording.graph)
    tracker = make_tracker(options.model)
    with open_video(recording.video) as src:
        points = load_annotations(recording.annotations, image_size=src.size)
        bad = [n for n in graph.nodes if not 0 <= n < len(points)]
        if bad:
            raise InputError(recording.graph, f"graph node {bad[0]} has no annotated point: "
                                              f"{recording.annotations} lists {len(points)} points", f"node {bad[0]}")
        tracked = tracker.track(src, points, graph=graph, max_frames=options.max_frames)
    return tracked.to_frame(), graph, time.perf_counter() - t0
