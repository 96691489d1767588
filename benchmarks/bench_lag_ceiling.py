"""What limits finding a hidden lag on the user's path: the same recordings diagnosed on better tracks (a ladder of
oracles; prints figures and saves the record ``user_path_lag_ceiling``).

``bench_user_path.py`` renders simulated branches with a hidden lag (delay or dynamics) as video, tracks them with
our tracker and runs the diagnosis (record ``user_path_lag``). On ``outdoor`` renders (blur, shadow, shake, x264 crf
28) the lag is found far less often than on crisp ones. This benchmark asks which part of the tracks costs it, by
diagnosing the same recordings (``rce diagnose``, default preset, seed 0) on five versions of their tracks, each
with our tracker's visibility and sigmas:

* ``ours``: our tracker's tracks, as ``rce run`` had them;
* ``no gross``: ours, with every visible point more than ``--gross-px`` from the truth marked lost (a tracker that
  knew its gross errors);
* ``true``: the true node positions (what the video shows, camera shake included);
* ``true + white S px``: the true positions plus white Gaussian noise of S px per axis (seeded by the recording's
  seed), for each S of ``--white``; the default sizes are our tracker's per-axis RMS error below ``--gross-px`` on
  these renders (0.32 px) and half of it.

For each version: how many hidden lags were found (named delay or dynamics), how many the one-node check withheld
(``settings.verdict_withheld``), and, for ``ours`` and ``no gross``, false verdicts on the effect-free recordings of
the same cache. The truth is re-simulated from each recording's ``truth.json`` (its config and camera shift); the
benchmark checks that the re-simulated excitation equals the recording's ``z_true`` and, where the recording kept
it, that the re-simulated noisy tracks equal its ``sim/tracks.csv``.

Usage: python benchmarks/bench_lag_ceiling.py --cache DIR [--first-seed 100] [--seeds 20] [--frames 450]
       [--effect-free-seeds 60] [--white 0.16,0.32] [--gross-px 2] [--workers 2] [--record user_path_lag_ceiling]
(DIR: the cache of ``bench_user_path.py``, with its ``outdoor`` cases of delay, dynamics and none; diagnoses are
cached in each case folder as ``diag_<version>.json``; for ``ours`` the ``rediagnosis.json`` that
``bench_user_path.py --rediagnose`` wrote is read where present. Delete them to re-measure after a change.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
BIN = Path(sys.executable).parent
LAG = {"delay", "dynamics"}


def true_positions(case: Path) -> np.ndarray:
    """(P, F, 2) px: the true node positions of a ``rce simulate --video`` recording as its video shows them (the
    simulator's true positions plus the render's camera shift), re-simulated from ``sim/truth.json``."""
    from rce_gtsam.sim.simulate import NoiseConfig, SimulationConfig, simulate

    truth = json.loads((case / "sim" / "truth.json").read_text())
    c = truth["config"]
    sim = simulate(SimulationConfig(n_nodes=c["n_nodes"], n_frames=c["n_frames"], effects=tuple(c["effects"]),
                                    seed=c["seed"], noise=NoiseConfig()))
    xy = np.zeros_like(sim.true_xy)
    xy[list(sim.tracks.node_ids)] = sim.true_xy
    shift = np.asarray(truth["render"].get("camera_shift_px") or np.zeros((xy.shape[1], 2)), float)
    if not np.allclose(sim.z_true, truth["z_true"], atol=1e-6):
        raise RuntimeError(f"{case}: the re-simulated excitation differs from truth.json's; the truth is not this "
                           f"recording's")
    written = case / "sim" / "tracks.csv"
    if written.exists():  # the recording's noisy tracks are the simulator's, moved by the camera as the video is
        again = sim.tracks.to_frame()
        again[["x", "y"]] += shift[again.frame.to_numpy()]
        merged = pd.read_csv(written).merge(again, on=["point_id", "frame"], suffixes=("", "_again"))
        if len(merged) != len(again) or not np.allclose(merged[["x", "y"]].to_numpy(),
                                                        merged[["x_again", "y_again"]].to_numpy(), atol=1e-3,
                                                        equal_nan=True):
            raise RuntimeError(f"{case}: the re-simulated tracks differ from sim/tracks.csv; the truth is not this "
                               f"recording's")
    return xy + shift[None]


def version_tracks(case: Path, version: str, gross_px: float) -> pd.DataFrame:
    """Our tracks of ``case`` made into ``version`` ("ours", "no gross", "true", "white:S")."""
    tracks = pd.read_csv(case / "run" / "tracks.csv")
    if version == "ours":
        return tracks
    xy = true_positions(case)
    t = xy[tracks.point_id.to_numpy(), tracks.frame.to_numpy()]
    if version == "no gross":
        err = np.hypot(tracks.x - t[:, 0], tracks.y - t[:, 1])
        tracks.loc[(tracks.visible == 1) & (err > gross_px), "visible"] = 0
        return tracks
    noise = float(version.split(":")[1]) if version.startswith("white:") else 0.0
    rng = np.random.default_rng(int(json.loads((case / "sim" / "truth.json").read_text())["seed"]))
    tracks["x"] = t[:, 0] + noise * rng.standard_normal(len(tracks))
    tracks["y"] = t[:, 1] + noise * rng.standard_normal(len(tracks))
    return tracks


def tag(version: str) -> str:
    return {"ours": "ours", "no gross": "g2", "true": "tru"}.get(version) or f"w{round(100 * float(version[6:]))}"


def diagnose(case: str, version: str, gross_px: float) -> dict:
    """The diagnosis of ``case`` on ``version`` of its tracks (cached as ``diag_<tag>.json``): its verdict row."""
    d = Path(case)
    out = d / f"diag_{tag(version)}.json"
    if version == "ours" and not out.exists() and (d / "rediagnosis.json").exists():
        out = d / "rediagnosis.json"  # bench_user_path.py --rediagnose's diagnosis of the same tracks
    if not out.exists():
        path = d / f"tracks_{tag(version)}.csv"
        version_tracks(d, version, gross_px).to_csv(path, index=False)
        subprocess.run([str(BIN / "rce"), "diagnose", str(path), str(d / "sim" / "graph.json"), "--json", str(out),
                        "--seed", "0", "--quiet"], capture_output=True, text=True)
    diag = json.loads(out.read_text())
    return {"case": d.name, "effect": d.name.split("_")[0], "version": version, "verdict": diag.get("verdict"),
            "withheld": ((diag.get("settings") or {}).get("verdict_withheld") or {}).get("effect")}


def error_stats(cases: list[str], gross_px: float) -> dict:
    """Our tracker's error on the visible points of ``cases`` against the truth: per-axis RMS of the errors below
    ``gross_px``, share of visible points beyond it and their share of the squared error."""
    err = []
    for c in cases:
        d = Path(c)
        tracks = pd.read_csv(d / "run" / "tracks.csv")
        tracks = tracks[tracks.visible == 1]
        t = true_positions(d)[tracks.point_id.to_numpy(), tracks.frame.to_numpy()]
        err.append(np.hypot(tracks.x.to_numpy() - t[:, 0], tracks.y.to_numpy() - t[:, 1]))
    e = np.concatenate(err)
    small = e[e <= gross_px]
    return {"rms_per_axis_below_px": float(np.sqrt(np.mean(small ** 2) / 2)),
            "share_beyond": float(np.mean(e > gross_px)),
            "sq_share_beyond": float(np.sum(e[e > gross_px] ** 2) / np.sum(e ** 2)), "median_px": float(np.median(e))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", required=True)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--effect-free-seeds", type=int, default=60)
    ap.add_argument("--white", default="0.16,0.32")
    ap.add_argument("--gross-px", type=float, default=2.0)
    ap.add_argument("--workers", type=int, default=max(1, os.cpu_count() or 2))
    ap.add_argument("--record", default=None, metavar="NAME")
    a = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    cache = Path(a.cache)

    def cases(effect, n):
        out = [cache / f"{effect}_outdoor_f{a.frames}_s{s}" for s in range(a.first_seed, a.first_seed + n)]
        return [str(c) for c in out if (c / "run" / "tracks.csv").exists()]

    lags = cases("delay", a.seeds) + cases("dynamics", a.seeds)
    free = cases("none", a.effect_free_seeds)
    versions = ["ours", "no gross", "true"] + [f"white:{w}" for w in a.white.split(",")]
    jobs = [(c, v) for v in versions for c in lags] + [(c, v) for v in ("ours", "no gross") for c in free]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(diagnose, *zip(*jobs), [a.gross_px] * len(jobs)))
    stats = error_stats(lags + free, a.gross_px)
    print(f"our tracker on these outdoor renders (visible points): median error {stats['median_px']:.3f} px; "
          f"{100 * stats['share_beyond']:.2f} % beyond {a.gross_px:g} px carry {100 * stats['sq_share_beyond']:.0f} % "
          f"of the squared error; per-axis RMS of the rest {stats['rms_per_axis_below_px']:.3f} px")
    table = []
    for v in versions:
        r = [x for x in rows if x["version"] == v]
        cell = {}
        for eff in ("delay", "dynamics"):
            rs = [x for x in r if x["effect"] == eff]
            cell[eff] = (sum(x["verdict"] in LAG for x in rs), len(rs), sum(x["withheld"] in LAG for x in rs))
        rf = [x for x in r if x["effect"] == "none"]
        found = cell["delay"][0] + cell["dynamics"][0]
        n = cell["delay"][1] + cell["dynamics"][1]
        name = v if not v.startswith("white:") else f"true + white {v[6:]} px"
        table.append([name, f"{cell['delay'][0]} of {cell['delay'][1]}",
                      f"{cell['dynamics'][0]} of {cell['dynamics'][1]}",
                      f"{found} of {n}", cell["delay"][2] + cell["dynamics"][2],
                      f"{sum(x['verdict'] is not None for x in rf)} of {len(rf)}" if rf else "-"])
    cols = ["tracks", "delay found", "dynamics found", "lag found", "withheld by the one-node check",
            "effect-free named"]
    print("  ".join(cols))
    for t in table:
        print("  ".join(str(x) for x in t))
    if a.record:
        from record import save_record
        save_record(a.record, title="What limits finding a hidden lag on outdoor video: the same recordings on better "
                                    "tracks",
                    command=(f"python benchmarks/bench_lag_ceiling.py --cache DIR --first-seed {a.first_seed} "
                             f"--seeds {a.seeds} --frames {a.frames} --effect-free-seeds {a.effect_free_seeds} "
                             f"--white {a.white} --gross-px {a.gross_px:g} (DIR: bench_user_path.py's cache)"),
                    description=("The outdoor recordings of record user_path_lag (450 frames, 20 nodes, seeds "
                                 f"{a.first_seed}-{a.first_seed + a.seeds - 1}; blur, shadow, shake, x264 crf 28), "
                                 "diagnosed (rce diagnose, default preset) on five versions of their tracks, each with "
                                 "our tracker's visibility and sigmas: ours; ours with every visible point more than "
                                 f"{a.gross_px:g} px from the truth marked lost; the true positions; the true "
                                 "positions plus white noise per axis. A lag counts as found when delay or dynamics "
                                 "is named. "
                                 "Effect-free: the outdoor effect-free recordings of record user_path."),
                    columns=cols, rows=table,
                    notes=[f"our tracker there (visible points): median error {stats['median_px']:.2f} px; "
                           f"{100 * stats['share_beyond']:.1f} % of points beyond {a.gross_px:g} px carry "
                           f"{100 * stats['sq_share_beyond']:.0f} % of the squared error; the rest has a per-axis RMS "
                           f"of {stats['rms_per_axis_below_px']:.2f} px"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
