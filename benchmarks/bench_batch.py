"""`rce batch` on Dask: wall time of N simulated recordings one by one vs on 1 and 2 workers.

Usage: python benchmarks/bench_batch.py [--recordings 8] [--frames 600] [--nodes 12] [--boot 250]
                                        [--effects offset,second_mode,nonlinear] [--figures] [--workers 1,2]
                                        [--repeats 2]

Makes N simulated track recordings (rce_gtsam.sim.simulate, seeds 0..N-1) and a manifest, then times, in
this process and run:

* one by one: the same per-recording work (analyze -> diagnose -> write the folder, the function each
  batch task runs) in a plain loop, no Dask — the baseline;
* ``rce_gtsam.batch.run`` (what ``rce batch`` runs) on a new LocalCluster with k single-threaded worker
  processes, for each k of ``--workers``;
* the same against a separately started ``dask scheduler`` + ``dask worker --nworkers k`` (processes
  this script starts on 127.0.0.1 and stops at the end), passed as ``--scheduler``.

Configurations are interleaved and repeated (``--repeats``); the fastest run of each is reported. Every
batch run writes into a fresh folder (nothing cached) and includes starting the cluster (LocalCluster
only), the summary, the comparison figures and batch.rrd. Speed-up = one-by-one time / batch time;
efficiency = speed-up / workers. Also the CPU seconds of all processes (this one and the LocalCluster's,
not the --scheduler workers), which load from other programs inflates much less than wall time. Also
checks that every run's kappa is bit-identical to the first run's.
Timings on a shared machine are noisy: compare the ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd


def make_inputs(root: Path, n: int, frames: int, nodes: int) -> Path:
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    rows = []
    for i in range(n):
        rid = f"r{i:02d}"
        simulate(SimulationConfig(n_nodes=nodes, n_frames=frames, seed=i)).write(root / rid)
        rows.append({"id": rid, "tracks": f"{rid}/tracks.csv", "graph": f"{rid}/graph.json", "plant": f"plant {i}"})
    manifest = root / "manifest.csv"
    pd.DataFrame(rows).to_csv(manifest, index=False)
    return manifest


def one_by_one(manifest: Path, out: Path, options) -> float:
    from rce_gtsam.batch import load_manifest
    from rce_gtsam.batch.options import fingerprint
    from rce_gtsam.batch.process import process_recording
    m = load_manifest(manifest)
    t0, c0 = time.perf_counter(), cpu_s()
    for rec in m.recordings:
        oc = process_recording(rec, out, options, fingerprint(rec, options)["hash"])
        if oc.status != "ok":
            raise SystemExit(f"{rec.id} failed: {oc.error}")
    return time.perf_counter() - t0, cpu_s() - c0


def cpu_s() -> float:
    """CPU seconds (user + system) of this process and of its children that ended (a LocalCluster's
    nannies, which reaped their workers): load from other programs inflates wall times, much less this."""
    import resource
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                  resource.getrusage(resource.RUSAGE_CHILDREN)))


def batch_run(manifest: Path, out: Path, options, **where) -> float:
    from rce_gtsam import batch
    t0, c0 = time.perf_counter(), cpu_s()
    res = batch.run(manifest, out, options=options, **where)
    wall = time.perf_counter() - t0
    cpu = cpu_s() - c0
    if res.count("ok") != len(res.outcomes):
        raise SystemExit(f"batch failed: {[o.error for o in res.failed]}")
    # with --scheduler the workers are not this process's finished children: their CPU is not counted
    return wall, {**res.timings_s, **({"cpu": cpu} if "scheduler" not in where else {})}


class SeparateCluster:
    """`dask scheduler` + `dask worker --nworkers k --nthreads 1` as child processes on 127.0.0.1."""

    def __init__(self, workers: int, tmp: Path):
        self.workers, self.tmp = workers, tmp
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> str:
        dask = str(Path(sys.executable).with_name("dask"))
        sfile = self.tmp / f"scheduler_{self.workers}.json"
        log = open(self.tmp / f"dask_{self.workers}.log", "w")
        self.procs.append(subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                                            "--no-dashboard", "--dashboard-address", "127.0.0.1:0",
                                            "--scheduler-file", str(sfile)],
                                           stdout=log, stderr=subprocess.STDOUT))
        for _ in range(600):
            if sfile.is_file() and sfile.stat().st_size:
                break
            time.sleep(0.1)
        # the workers as the README starts them: without Dask's statistical profiler (see
        # rce_gtsam.batch.runner.LOCAL_WORKER_CONFIG, which the LocalCluster of `rce batch` uses)
        env = {**os.environ, "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False"}
        self.procs.append(subprocess.Popen([dask, "worker", "--scheduler-file", str(sfile), "--host", "127.0.0.1",
                                            "--nworkers", str(self.workers), "--nthreads", "1", "--no-dashboard"],
                                           stdout=log, stderr=subprocess.STDOUT, env=env))
        from distributed import Client
        with Client(scheduler_file=str(sfile), timeout="60s") as c:
            c.wait_for_workers(self.workers, timeout=180)
            return c.scheduler.address

    def __exit__(self, *exc):
        for p in reversed(self.procs):  # only the processes this object started, by their handles
            p.terminate()
        for p in reversed(self.procs):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def _phases(ph: dict) -> str:
    return "(" + ", ".join(f"{k} {v:.1f}" for k, v in ph.items()) + ")"


def kappa_of(out: Path) -> pd.DataFrame:
    return pd.concat([pd.read_csv(f).assign(id=f.parent.name) for f in sorted(out.glob("r*/compliance_summary.csv"))])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recordings", type=int, default=8)
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--nodes", type=int, default=12)
    ap.add_argument("--boot", type=int, default=250)
    ap.add_argument("--effects", default="offset,second_mode,nonlinear")
    ap.add_argument("--figures", action="store_true", help="also write the per-recording figures")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--repeats", type=int, default=2, help="runs of each configuration; the fastest is reported")
    args = ap.parse_args()
    from rce_gtsam.batch import BatchOptions
    options = BatchOptions(n_boot=args.boot, seed=0, effects=args.effects, figures=args.figures)
    ks = [int(k) for k in args.workers.split(",")]
    tmp = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        manifest = make_inputs(tmp / "in", args.recordings, args.frames, args.nodes)
        print(f"{args.recordings} simulated recordings, {args.frames} frames x {args.nodes} nodes, bootstrap "
              f"{args.boot}, diagnosis candidates {args.effects}, per-recording figures "
              f"{'on' if args.figures else 'off'}", flush=True)
        configs = [("one by one (no Dask)", 1, None)]
        configs += [("rce batch, LocalCluster", k, "local") for k in ks]
        configs += [("rce batch --scheduler (dask scheduler + dask worker)", k, "scheduler") for k in ks]
        best: dict[int, tuple[float, dict]] = {}
        ref = None
        for rep in range(args.repeats):  # configurations interleaved, so a burst of load hits all of them
            for i, (name, k, kind) in enumerate(configs):
                out = tmp / f"run{rep}_{i}"
                if kind is None:
                    t, cpu = one_by_one(manifest, out, options)
                    ph = {"compute": t, "cpu": cpu}
                elif kind == "local":
                    t, ph = batch_run(manifest, out, options, workers=k)
                else:
                    with SeparateCluster(k, tmp) as address:
                        t, ph = batch_run(manifest, out, options, scheduler=address)
                kap = kappa_of(out)
                if ref is None:
                    ref = kap
                pd.testing.assert_frame_equal(kap, ref, check_exact=True)
                shutil.rmtree(out)
                print(f"  [{rep + 1}/{args.repeats}] {name}, {k} worker(s): {t:.1f} s {_phases(ph)}", flush=True)
                if i not in best or t < best[i][0]:
                    best[i] = (t, ph)
        rows = [(name, k, *best[i]) for i, (name, k, _) in enumerate(configs)]
        t_seq, cpu_seq = rows[0][2], rows[0][3]["cpu"]
        print("\n| run | workers | wall (s) | speed-up | efficiency | compute phase (s) | its speed-up | its efficiency "
              "| cluster start + stop + summary (s) | CPU, all processes (s) | CPU / one by one |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for name, k, t, ph in rows:
            c = ph.get("compute", float("nan"))
            rest = ph.get("cluster_start", 0.0) + ph.get("cluster_stop", 0.0) + ph.get("summary", 0.0)
            print(f"| {name} | {k} | {t:.1f} | {t_seq / t:.2f} | {t_seq / t / k:.2f} | {c:.1f} | {t_seq / c:.2f} | "
                  f"{t_seq / c / k:.2f} | {rest:.1f} | {ph.get('cpu', float('nan')):.1f} | "
                  f"{ph.get('cpu', float('nan')) / cpu_seq:.2f} |")
        print("speed-up = one-by-one wall / this wall; efficiency = speed-up / workers; the compute phase runs "
              "from the first task submitted to the last result; CPU: user + system seconds of this process and "
              "its ended children (the LocalCluster's nannies and workers; not counted with --scheduler)")
        print(f"(fastest of {args.repeats} interleaved runs per configuration)")
        print("\nkappa of every run is bit-identical to the first one-by-one run (all recordings, all segments).")
        print(json.dumps({"rows": [{"run": n, "workers": k, "wall_s": round(t, 2),
                                    "phases_s": {a: round(b, 2) for a, b in ph.items()}} for n, k, t, ph in rows]}))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
