"""Wall time of the command line as a user waits for it, against a plain numpy/scipy process, in one run.

Usage: python benchmarks/bench_cli.py [--plant DIR] [--repeat 3] [--no-diagnose] [--baseline REV]

Prints one table:
1. `rce --help` and an argument error (`rce analyze` without arguments): best of 5 subprocesses (goal < 0.5 s);
2. `rce analyze` on the plant (default and paper presets, 250 resamples, figures included) against
   benchmarks/reference_numpy.py, the published computation as one plain numpy/scipy process (moving average,
   sparse least-squares smoother, angles, MAD, rank-1 ALS, 250 block-bootstrap refits): both timed as whole
   subprocesses, imports included, runs interleaved so both see the same machine load; median of --repeat
   and the ratio (goal <= 2x); also the total `rce analyze` printed (it should match its wall time) and the
   CPU seconds of each (user + sys, figure worker included): on a shared machine the CPU ratio is the steadier
   figure;
3. `rce diagnose` on the plant (all five candidates): wall time, once; with ``--baseline REV`` --repeat times, runs
   interleaved with the same command of revision REV (its ``rce_gtsam`` and ``factors``, exported from git and run
   from a temporary folder), medians, the ratio and whether the two diagnosis.json files agree (every number to
   1e-6 relative, the timings left out).
The machine may be shared: read the ratios.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RCE = [sys.executable, "-m", "rce_gtsam.cli"]


CPU: list[float] = []  # CPU seconds (user + sys, the process and its children) of each wall() call


def wall(cmd, env=None) -> tuple[float, str]:
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    CPU.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    if p.returncode not in (0, 2):
        raise SystemExit(f"{' '.join(map(str, cmd))} failed:\n{p.stderr}")
    return dt, p.stdout


#: runs ``rce_gtsam.cli`` from the folder in $RCE_FROM instead of the editable install (whose import hook would
#: otherwise win over any path)
FROM_FOLDER = ("import os, runpy, sys; sys.meta_path[:] = [f for f in sys.meta_path "
               "if not type(f).__module__.startswith('__editable__')]; sys.path.insert(0, os.environ['RCE_FROM']); "
               "sys.argv[0] = 'rce'; runpy.run_module('rce_gtsam.cli', run_name='__main__')")


def export_revision(rev: str, dest: Path) -> tuple[list[str], dict]:
    """Export revision ``rev``'s package (``rce_gtsam`` with ``factors`` as ``rce_gtsam.factors``, the installed
    layout) into ``dest``; returns (the command that runs its ``rce``, its environment)."""
    arch = subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", rev, "rce_gtsam", "factors"],
                          capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(arch)) as tar:
        tar.extractall(dest, filter="data")
    (dest / "factors").rename(dest / "rce_gtsam" / "factors")
    return [sys.executable, "-c", FROM_FOLDER], dict(os.environ, RCE_FROM=str(dest))


def same_numbers(a, b, rtol: float = 1e-6) -> bool:
    """True when two JSON values agree: the same keys, strings and flags, every number to ``rtol`` relative, NaN
    where the other is NaN (keys that name seconds, the run's timings, are not compared)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_numbers(a[k], b[k], rtol) for k in a if "second" not in k)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same_numbers(x, y, rtol) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        if not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
            return False
        return (a != a and b != b) or abs(a - b) <= rtol * max(abs(a), 1e-9)  # x != x: NaN
    return a == b


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plant", type=Path, default=next(
        (p for p in (REPO.parent / "shared" / "data" / "plant_1", REPO.parents[1] / "shared" / "data" / "plant_1")
         if p.is_dir()), REPO.parent / "shared" / "data" / "plant_1"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-diagnose", action="store_true")
    ap.add_argument("--baseline", default=None, metavar="REV",
                    help="also time rce diagnose of this git revision, interleaved (e.g. HEAD~3)")
    args = ap.parse_args()
    tracks, graph = args.plant / "tapir_tracks.csv", args.plant / "branch_graph.json"
    rows = []
    for label, cmd in (("rce --help", [*RCE, "--help"]), ("rce analyze (argument error)", [*RCE, "analyze"])):
        rows.append((label + ", best of 5", min(wall(cmd)[0] for _ in range(5)), "goal < 0.5 s"))
    ref, printed, cpu = [], {}, {"ref": [], "default": [], "paper": []}
    rce = {"default": [], "paper": []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):
            ref.append(wall([sys.executable, str(REPO / "benchmarks" / "reference_numpy.py"), tracks, graph])[0])
            cpu["ref"].append(CPU[-1])
            for preset in rce:
                dt, out = wall([*RCE, "analyze", tracks, graph, "--out", f"{tmp}/{preset}{i}", "--quiet",
                                "--preset", preset])
                rce[preset].append(dt)
                cpu[preset].append(CPU[-1])
                printed.setdefault(preset, []).append(float(out.split("\ntotal ")[1].split()[0]))
        t_ref = statistics.median(ref)
        c_ref = statistics.median(cpu["ref"])
        rows.append((f"plain numpy/scipy process of the published computation ({args.plant.name})", t_ref,
                     f"median of {args.repeat}: {', '.join(f'{v:.2f}' for v in ref)}; CPU {c_ref:.2f} s"))
        for preset, times in rce.items():
            t = statistics.median(times)
            rows.append((f"rce analyze {args.plant.name} --preset {preset}, figures included", t,
                         f"median of {args.repeat}: {', '.join(f'{v:.2f}' for v in times)}; ratio "
                         f"{t / t_ref:.2f}x the plain process (goal <= 2x); printed totals "
                         f"{', '.join(f'{v:.2f}' for v in printed[preset])}; CPU "
                         f"{statistics.median(cpu[preset]):.2f} s = {statistics.median(cpu[preset]) / c_ref:.2f}x"))
        if not args.no_diagnose and args.baseline is None:
            dt, _ = wall([*RCE, "diagnose", tracks, graph, "--json", f"{tmp}/d.json", "--quiet"])
            rows.append((f"rce diagnose {args.plant.name}, all five candidates", dt, "once"))
        elif not args.no_diagnose:
            rce_base, env = export_revision(args.baseline, Path(tmp) / "baseline")
            cmd = ["diagnose", tracks, graph, "--quiet", "--json"]
            now, base = [], []
            for i in range(args.repeat):
                base.append(wall([*rce_base, *cmd, f"{tmp}/b.json"], env=env)[0])
                now.append(wall([*RCE, *cmd, f"{tmp}/n.json"])[0])
            same = same_numbers(json.loads(Path(f"{tmp}/b.json").read_text()),
                                json.loads(Path(f"{tmp}/n.json").read_text()))
            tb, tn = statistics.median(base), statistics.median(now)
            rows.append((f"rce diagnose {args.plant.name} at {args.baseline}", tb,
                         f"median of {args.repeat}: {', '.join(f'{v:.2f}' for v in base)}"))
            rows.append((f"rce diagnose {args.plant.name}, this checkout", tn,
                         f"median of {args.repeat}: {', '.join(f'{v:.2f}' for v in now)}; ratio {tn / tb:.2f}x the "
                         f"baseline; diagnosis.json {'the same' if same else 'differs'} (numbers to 1e-6)"))
    width = max(len(r[0]) for r in rows)
    for label, t, note in rows:
        print(f"{label:<{width}}  {t:6.2f} s  {note}")


if __name__ == "__main__":
    main()
