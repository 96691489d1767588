"""The diagnosis spread over worker processes (rce_gtsam.diagnosis.parallel) gives the diagnosis the serial loop
gives, and falls back to the serial loop where a process may not fork."""

from __future__ import annotations

import json
import multiprocessing as mp
import sys
from pathlib import Path

from _effect_data import synth
from rce_gtsam.diagnosis.diagnose import diagnose
from rce_gtsam.diagnosis.parallel import default_workers, map_candidates

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_cli import same_numbers  # noqa: E402 - the comparison bench_cli --baseline makes


def test_two_workers_give_the_serial_diagnosis():
    """Every candidate that has alternative starts (dynamics, resonances) and one that has none, on a recording
    with a hidden delay: the same verdict, candidates, numbers and report as the serial run."""
    Y, s, *_ = synth("delay", seed=3, E=10, T=400)
    kw = dict(root_distance=s, effects=["delay", "dynamics", "resonances", "offset"],
              edge_nodes=[{i} for i in range(10)])
    serial, parallel = diagnose(Y, **kw), diagnose(Y, **kw, workers=2)
    assert serial.verdict == parallel.verdict == "delay"
    a, b = (json.loads(json.dumps(d.as_dict(), default=float)) for d in (serial, parallel))
    assert same_numbers(a, b, rtol=1e-9)
    assert serial.report() == parallel.report()


def _square(x: int) -> int:
    return x * x


def _in_a_daemon(queue) -> None:
    queue.put(map_candidates(_square, [(i,) for i in range(5)], workers=2))


def test_a_daemonic_process_runs_the_candidates_serially():
    """A Dask or multiprocessing worker is daemonic and may not start processes: there the map runs in the
    process itself and still returns every result in order."""
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_in_a_daemon, args=(q,), daemon=True)
    p.start()
    out = q.get(timeout=60)
    p.join(timeout=60)
    assert out == [0, 1, 4, 9, 16] and p.exitcode == 0
    assert map_candidates(_square, [(3,)], workers=4) == [9]
    assert 1 <= default_workers() <= 2
