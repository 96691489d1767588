"""Run a manifest of recordings on a Dask cluster and summarise them: :func:`run`.

Steps: validate the manifest and the options (an :class:`~rce_gtsam.errors.InputError` before any
work); fingerprint every recording (input file contents + resolved preset + options); reuse the stored
outcome of each recording whose fingerprint and outputs are unchanged; submit the rest, one task per
recording (:func:`rce_gtsam.batch.process.process_recording`), to a ``dask.distributed`` cluster — the
``client`` given, the scheduler at ``scheduler`` or a new ``LocalCluster`` (one single-threaded worker
process per core, at most one per recording: the pipeline holds the GIL); then write ``summary.csv``,
``summary.json``, ``figures/`` and ``batch.rrd`` into the output folder.

Nothing is submitted (and no cluster started) when every recording is up to date.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from ..errors import InputError
from .manifest import Manifest, load_manifest
from .options import BatchOptions, fingerprint
from .process import Outcome, process_recording, stored_outcome, write_record

SUMMARY_CSV, SUMMARY_JSON, FIGURES_DIR, RECORDING_RRD = "summary.csv", "summary.json", "figures", "batch.rrd"

#: Dask settings of the workers of the LocalCluster :func:`run` starts. The worker's statistical profiler
#: (a stack sample of the task thread every 10 ms, taken under the GIL) cost ~16 % of a recording's CPU
#: time (12.5 s vs 15.2 s of process CPU for 8 simulated recordings, benchmarks/bench_batch.py sizes);
#: nobody looks at the profile of a batch. Workers started with ``dask worker`` take the same setting from
#: the environment: ``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False dask worker ...``.
LOCAL_WORKER_CONFIG = {"distributed.worker.profile.enabled": False}


@dataclass(frozen=True)
class BatchResult:
    """What :func:`run` did. outcomes: per recording id (manifest order). summary: the ``summary.csv``
    table. files: {name: path} of the batch-level outputs. wall_s: seconds for the whole call; timings_s:
    its phases ("prepare": manifest and fingerprints, "cluster_start", "compute": from the first task
    submitted to the last result, "cluster_stop": closing the client and the cluster :func:`run` started,
    "summary": summary, figures and recording).
    cluster: how the work was run ({"kind": "none" | "client" | "scheduler" | "local", ...})."""

    out: Path
    outcomes: dict[str, Outcome]
    summary: pd.DataFrame
    files: dict[str, Path] = field(default_factory=dict)
    wall_s: float = 0.0
    timings_s: dict = field(default_factory=dict)
    cluster: dict = field(default_factory=dict)

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes.values())

    @property
    def failed(self) -> list[Outcome]:
        return [o for o in self.outcomes.values() if o.status == "failed"]


def default_workers(n_tasks: int) -> int:
    """Worker processes for a LocalCluster: the usable cores, at most one per task (>= 1)."""
    return max(1, min(usable_cores(), n_tasks))


def start_local_cluster(n_workers: int):
    """The ``distributed.LocalCluster`` of :func:`run`: ``n_workers`` single-threaded worker processes
    with :data:`LOCAL_WORKER_CONFIG`, the dashboard on any free port (so concurrent clusters do not fight
    over 8787)."""
    import dask
    from distributed import LocalCluster
    with dask.config.set(LOCAL_WORKER_CONFIG):  # the nannies hand this config to the worker processes
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0")


def usable_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def run(manifest: str | Path | Manifest, out: str | Path, client=None, *, scheduler: str | None = None,
        workers: int | None = None, options: BatchOptions | None = None, progress: bool = False,
        recording: bool = True) -> BatchResult:
    """Run every recording of ``manifest`` into ``out/<id>/`` on Dask and write the batch summary.

    ``client``: a ``distributed.Client`` to use (not closed). Else ``scheduler`` (``tcp://HOST:PORT`` of a
    running ``dask scheduler``), else a new ``LocalCluster`` with ``workers`` single-threaded worker
    processes (default :func:`default_workers`), closed at the end. ``options``: the settings shared by
    every recording (:class:`BatchOptions`; default: the ``default`` preset, as ``rce run``). ``progress``:
    a tqdm bar over recordings on stderr. ``recording``: also write ``batch.rrd``.
    A failed recording is reported in the outcome and the summary and does not stop the others.
    """
    t0 = time.perf_counter()
    m = manifest if isinstance(manifest, Manifest) else load_manifest(manifest)
    options = options or BatchOptions()
    if workers is not None and workers < 1:
        raise InputError("--workers", f"must be >= 1, got {workers}")
    for rec in m.recordings:
        options.preset_for(rec)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "the output path exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)

    fps = {rec.id: fingerprint(rec, options)["hash"] for rec in m.recordings}
    outcomes: dict[str, Outcome] = {}
    todo = []
    for rec in m.recordings:
        stored = stored_outcome(out / rec.id, fps[rec.id])
        if stored is not None:
            outcomes[rec.id] = stored
        else:
            todo.append(rec)

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(m.recordings), initial=len(m.recordings) - len(todo), unit="recording",
                   desc="batch", file=sys.stderr, dynamic_ncols=True)
    cluster_info = {"kind": "none"}
    timings = {"prepare": time.perf_counter() - t0}
    try:
        if todo:
            cluster_info = _compute(todo, out, options, fps, outcomes, client, scheduler, workers, bar, timings,
                                    recording)
    finally:
        if bar is not None:
            bar.close()
    outcomes = {rec.id: outcomes[rec.id] for rec in m.recordings}
    t_summary = time.perf_counter()
    key = _summary_key(m, outcomes, recording)
    reused = _unchanged_summary(out, key) if cluster_info["kind"] == "none" else None
    if reused is not None:
        files, table = reused
    else:
        files, table = _write_summary(m, out, outcomes, options, recording,
                                      {"key": key, "cluster": cluster_info, "timings_s": timings})
    timings["summary"] = time.perf_counter() - t_summary
    return BatchResult(out=out, outcomes=outcomes, summary=table, files=files, wall_s=time.perf_counter() - t0,
                       cluster=cluster_info, timings_s=timings)


def _compute(todo, out: Path, options: BatchOptions, fps: dict, outcomes: dict, client, scheduler, workers,
             bar, timings: dict, recording: bool) -> dict:
    """Submit ``todo`` to the cluster and fill ``outcomes`` as tasks finish. Returns the cluster info."""
    t0 = time.perf_counter()
    from distributed import Client, as_completed

    own_cluster = own_client = None
    if client is not None:
        info = {"kind": "client", "scheduler": client.scheduler.address}
    elif scheduler is not None:
        try:
            client = own_client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise InputError("--scheduler", f"cannot connect to {scheduler}: {exc}") from None
        info = {"kind": "scheduler", "scheduler": scheduler}
    else:
        n = workers or default_workers(len(todo))
        own_cluster = start_local_cluster(n)
        client = own_client = Client(own_cluster)
        info = {"kind": "local", "workers": n, "threads_per_worker": 1}
    info["n_workers"] = len(client.scheduler_info().get("workers", {}))
    timings["cluster_start"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    warm = _SummaryWarmUp(recording)
    try:
        futures = {client.submit(process_recording, rec, str(out), options, fps[rec.id], pure=False,
                                 key=f"rce-batch-{rec.id}-{fps[rec.id][:12]}"): rec for rec in todo}
        remaining, cores = len(futures), usable_cores()
        warm.start_if(min(remaining, info["n_workers"] or 1) < cores)  # a core is idle: prepare the summary
        for fut in as_completed(futures):
            remaining -= 1
            warm.start_if(min(remaining, info["n_workers"] or 1) < cores)
            rec = futures[fut]
            try:
                oc = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker or an unpicklable error: record it
                oc = Outcome(id=rec.id, status="failed", fingerprint=fps[rec.id], error_kind="error",
                             error=" ".join(f"{type(exc).__name__}: {exc}".split()))
                write_record(out / rec.id, rec, oc, [])
            outcomes[rec.id] = oc
            if bar is not None:
                bar.update(1)
                if oc.status == "failed":
                    bar.write(f"{rec.id}: failed: {oc.error}", file=sys.stderr)
        timings["compute"] = time.perf_counter() - t0
    finally:
        warm.join()
        t0 = time.perf_counter()
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
        timings["cluster_stop"] = time.perf_counter() - t0
    return info


class _SummaryWarmUp:
    """Imports what the summary needs (matplotlib with its fonts; Rerun and the loggers when
    ``recording``) in a thread of this process, started while a core is idle during the compute phase
    (the cluster has fewer busy workers than cores), so the summary starts drawing at once. An error
    here is left for the summary itself to raise."""

    def __init__(self, recording: bool):
        self.recording, self.thread = recording, None

    def start_if(self, idle_core: bool) -> None:
        """Start the imports (once) when ``idle_core``."""
        if idle_core and self.thread is None:
            import threading
            self.thread = threading.Thread(target=self._run, name="rce-batch-warm-up", daemon=True)
            self.thread.start()

    def _run(self) -> None:
        try:
            from .figures import prepare_matplotlib
            prepare_matplotlib()
            if self.recording:
                from . import recording  # noqa: F401 - rerun, the loggers, the analysis view
                from ..viz import rerun_log, scene  # noqa: F401
        except Exception:  # noqa: BLE001 - see the class docstring
            pass

    def join(self) -> None:
        """Wait for the imports: the summary forks, which must not happen mid-import."""
        if self.thread is not None:
            self.thread.join()


def _summary_key(m: Manifest, outcomes: dict, recording: bool) -> str:
    """Hash of what the batch outputs show: the manifest's contents and every recording's fingerprint and
    status. Equal keys: the stored summary, figures and recording are still right."""
    import hashlib
    import json

    from .options import file_digest
    blob = json.dumps({"manifest": file_digest(m.path), "recording": recording,
                       "outcomes": [[o.id, o.fingerprint, o.status == "failed", o.error] for o in outcomes.values()]})
    return hashlib.sha256(blob.encode()).hexdigest()


def _unchanged_summary(out: Path, key: str):
    """(files, table) of the stored batch outputs when they were written for ``key`` and all exist, else None."""
    import json
    try:
        stored = json.loads((out / SUMMARY_JSON).read_text())["batch"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    files = {name: out / name for name in stored.get("files", [])}
    if stored.get("key") != key or not files or not all(p.is_file() for p in files.values()):
        return None
    return files, pd.read_csv(out / SUMMARY_CSV)


def _write_summary(m: Manifest, out: Path, outcomes: dict, options: BatchOptions, recording: bool,
                   batch: dict) -> tuple[dict[str, Path], pd.DataFrame]:
    from ..diagnosis.io import write_json_atomic
    from ..tracks import write_table_atomic
    from .figures import write_batch_figures
    from .summary import read_recordings, summary_document, summary_table

    recs = read_recordings(m, out, outcomes, options)
    table = summary_table(m, recs)
    files = {SUMMARY_CSV: out / SUMMARY_CSV}
    write_table_atomic(table, out / SUMMARY_CSV)
    # the figures are drawn in a forked process while this one writes the recording's plants (both take
    # about as long); the recording logs the figures last, once they are drawn
    from ..cli.figure_worker import FigureWorker
    with FigureWorker() as drawer:
        drawer.submit(write_batch_figures, recs, out / FIGURES_DIR)
        drawn: dict = {}

        def figures() -> dict:
            if not drawn:
                drawn.update(drawer.results()[0])
            return drawn

        if recording:
            from .recording import save_batch_recording
            files[RECORDING_RRD] = save_batch_recording(recs, out / RECORDING_RRD, figures=figures)
        files.update({f"{FIGURES_DIR}/{k}": v for k, v in figures().items()})
    counts = {s: sum(o.status == s for o in outcomes.values()) for s in ("ok", "skipped", "failed")}
    doc = summary_document(m, recs, {
        "manifest": str(m.path.resolve()), "out": str(out.resolve()), "n_recordings": len(m.recordings),
        "n_computed": counts["ok"], "n_skipped": counts["skipped"], "n_failed": counts["failed"],
        "metadata_columns": list(m.metadata_columns),
        "options": {"preset": options.preset, "overrides": list(options.overrides), "seed": options.seed,
                    "n_boot": options.n_boot, "effects": options.effects, "figures": options.figures,
                    "max_frames": options.max_frames, "model": None if options.model is None else str(options.model)},
        **batch, "files": sorted([*files, SUMMARY_JSON])})
    files[SUMMARY_JSON] = write_json_atomic(doc, out / SUMMARY_JSON)
    return files, table
