"""The swing's signature (:mod:`rce_gtsam.diagnosis.swing_signature`): do neighbouring segments change together?

``out_of_plane`` is named only where the length channel's test fires (p <= ALPHA_OOP: node-disjoint segments share
a course) *and* neighbouring segments' loadings on that course agree (sign-flip p <= ALPHA_AGREE). This benchmark
counts, per source, how often each fires and how often both do:

* the simulator's tracks (``rce simulate``'s tracker noise and artifact families): swings at the default share
  (0.5) with the branch plane tilted 30 deg (the length change first order in the swing) and in the image plane
  (tilt 0: second order), and planar recordings with every tracker-artifact family at 1x and 2x its measured size;
* ``--user-path DIR``: the folders of ``benchmarks/bench_user_path.py --cache DIR`` (``rce simulate --video`` ->
  our tracker), effect-free and ``out_of_plane`` renders, clean and ``outdoor``: the user's path;
* ``--bed-seeds``: the texture bed (real plant texture, known planar motion, H.264 at crf 23;
  ``bench_texture_bed.py``'s cache) through our tracker, effect-free and delayed: a tracker error common to the
  nodes, on data the rule was found on (so not its check: the two sources above are).

Columns: recordings; the length test fires (p <= 0.01); both fire (what naming needs first; on planar recordings
these are false alarms); the median agreement of neighbouring loadings where the length test fires (about +1 for a
swing, -1/2 for node parts of a shared course).

With ``--verdicts`` also the user path's verdicts (``rce diagnose``'s diagnosis) with and without the signature.

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_swing_signature.py [--seeds 20] [--frames 450]
       [--families none,slide,gust_occlusion,speed_error,lag,coloured_along,drift] [--user-path DIR [--verdicts]]
       [--bed-seeds 0,1,2,3,4] [--record swing_signature]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))


def length_test(res):
    """The length channel's LengthTest of an analysis (None: too few segments)."""
    from rce_gtsam.effects.out_of_plane import OutOfPlane
    return OutOfPlane.for_analysis(res).length_test(seed=0)


def row(source: str, condition: str, tests: list) -> list:
    """[source, condition, n, length fires, both fire, median agreement where the length test fires]."""
    from rce_gtsam.diagnosis.length_channel import ALPHA_OOP
    from rce_gtsam.diagnosis.swing_signature import ALPHA_AGREE

    p = np.array([1.0 if t is None else t.p for t in tests])
    g = np.array([1.0 if t is None else t.agreement_p for t in tests])
    rho = np.array([np.nan if t is None else t.agreement for t in tests])
    fires = p <= ALPHA_OOP
    both = fires & (g <= ALPHA_AGREE)
    med = round(float(np.median(rho[fires])), 2) if fires.any() else "-"
    n = len(tests)
    out = [source, condition, n, f"{int(fires.sum())} of {n}", f"{int(both.sum())} of {n}", med]
    print(f"  {source:22s} {condition:38s} length {out[3]:>9s}   both {out[4]:>9s}   agreement {med}", flush=True)
    return out


def simulator(a) -> list:
    from bench_out_of_plane import recording

    rows = []
    for name, share, tilt in (("swing, plane tilted 30 deg", 0.5, 30.0), ("swing, plane in the image", 0.5, 0.0)):
        rows.append(row("simulator tracks", name, [length_test(recording(s, a.frames, share, tilt)[2])
                                                   for s in range(a.seeds)]))
    for fam in a.families:
        for k in ((1.0,) if fam == "none" else (1.0, 2.0)):
            rows.append(row("simulator tracks", "planar, " + (fam if fam == "none" else f"{fam} {k:g}x"),
                            [length_test(recording(s, a.frames, 0.0, None, None if fam == "none" else fam, k)[2])
                             for s in range(a.seeds)]))
    return rows


def user_path(cache: Path, verdicts: bool = False) -> tuple[list, list]:
    """Rows from bench_user_path.py's case folders in ``cache`` (tracks through the default preset, no bootstrap),
    and with ``verdicts`` the diagnosis' verdicts with and without the signature, where the length test fires (it
    changes nothing elsewhere): rows [condition, cases, named out_of_plane without / with, other verdicts]."""
    from rce_gtsam.pipeline import analyze

    groups: dict = {}
    named: dict = {}
    for d in sorted(cache.iterdir()):
        tracks, graph = d / "run" / "tracks.csv", d / "sim" / "graph.json"
        if not (tracks.is_file() and graph.is_file()):
            continue
        effect, render = d.name.split("_f")[0].rsplit("_", 1)
        t = length_test(analyze(tracks, graph, n_boot=0))
        groups.setdefault((effect, render), []).append(t)
        if verdicts:
            named.setdefault((effect, render), []).append(verdict_pair(tracks, graph, t))
    rows = [row("user path (our tracker)", f"{'planar' if e == 'none' else 'swing'}, {e}, {r} render", t)
            for (e, r), t in sorted(groups.items())]
    vrows = []
    for (e, r), pairs in sorted(named.items()):
        before = sum(b == "out_of_plane" for b, _ in pairs)
        after = sum(a == "out_of_plane" for _, a in pairs)
        other = sorted({a for _, a in pairs if a not in (None, "out_of_plane")})
        vrows.append([f"{'planar' if e == 'none' else 'swing'}, {r} render", len(pairs), f"{before} / {after}",
                      ", ".join(other) or "-"])
        print(f"  verdicts, {vrows[-1][0]:24s} out_of_plane named without / with the signature: {vrows[-1][2]} of "
              f"{len(pairs)}; other verdicts (with): {vrows[-1][3]}", flush=True)
    return rows, vrows


def verdict_pair(tracks: Path, graph: Path, test) -> tuple:
    """(verdict without the signature, verdict with it) of ``rce diagnose``'s diagnosis (two workers) of a case; where
    the length test does not fire the two are the same and only one is run."""
    from unittest import mock

    from rce_gtsam.diagnosis.io import diagnose_result
    from rce_gtsam.diagnosis.length_channel import ALPHA_OOP
    from rce_gtsam.pipeline import analyze

    res = analyze(tracks, graph)
    after = diagnose_result(res, workers=2).verdict
    if test is None or test.p > ALPHA_OOP:
        return after, after
    with mock.patch("rce_gtsam.diagnosis.own_family.signature_holds", lambda own: True):
        before = diagnose_result(res, workers=2).verdict
    return before, after


def texture_bed(seeds: list[int]) -> list:
    from bench_texture_bed import PLANT, default_cache
    from bench_texture_errors import cached_tracks
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.track import LKTracker
    from rce_gtsam.tracks import Tracks

    if not (PLANT / "annotated_nodes.mp4").is_file():
        print(f"  texture bed skipped: plant 2 footage not found at {PLANT}")
        return []
    import subprocess
    # the tracks are cached under the last revision that changed the tracker
    rev = subprocess.run(["git", "-C", str(ROOT), "log", "-1", "--format=%h", "--", "rce_gtsam/track"],
                         capture_output=True, text=True).stdout.strip() or "worktree"
    rows = []
    for cond in ("none", "delay"):
        tests = []
        for seed in seeds:
            bed, cf, tr = cached_tracks(seed, () if cond == "none" else (cond,), 300, 60.0, default_cache(),
                                        LKTracker, rev)
            nodes, vis = list(cf.graph.nodes), tr["vis"]
            t = Tracks(node_ids=np.array(nodes), xy=np.where(vis[..., None], tr["xy"], np.nan)[nodes],
                       sigma_px=np.where(vis, tr["sig"], np.nan)[nodes], source="texture bed")
            tests.append(length_test(analyze(t, cf.graph, n_boot=0)))
        rows.append(row("texture bed (our tracker)", f"planar, {'effect-free' if cond == 'none' else 'delay'}", tests))
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--families", default="none,slide,gust_occlusion,speed_error,lag,coloured_along,drift")
    ap.add_argument("--user-path", type=Path, default=None, help="bench_user_path.py's --cache folder")
    ap.add_argument("--verdicts", action="store_true",
                    help="with --user-path: the diagnosis' verdicts with and without the signature (rce diagnose)")
    ap.add_argument("--bed-seeds", default="", help="texture bed seeds, e.g. 0,1,2,3,4 (needs ../shared)")
    ap.add_argument("--skip-simulator", action="store_true")
    ap.add_argument("--record", default=None, metavar="NAME")
    a = ap.parse_args(argv)
    a.families = [f for f in a.families.split(",") if f]
    warnings.filterwarnings("ignore")
    from rce_gtsam.diagnosis.length_channel import ALPHA_OOP
    from rce_gtsam.diagnosis.swing_signature import ALPHA_AGREE

    print(f"length test p <= {ALPHA_OOP}; neighbouring loadings agree, p <= {ALPHA_AGREE}")
    rows = [] if a.skip_simulator else simulator(a)
    vrows = []
    if a.user_path:
        up, vrows = user_path(a.user_path, a.verdicts)
        rows += up
    if a.bed_seeds:
        rows += texture_bed([int(s) for s in a.bed_seeds.split(",")])
    if a.record:
        from record import save_record
        cmd = " ".join(["python benchmarks/bench_swing_signature.py"] + (argv if argv is not None else sys.argv[1:]))
        title = "out_of_plane: the shared length course and the swing's signature, on swings and planar recordings"
        save_record(a.record, title=title, command=cmd,
                    description=(f"Per source and condition: recordings; how often the length channel's test fires "
                                 f"(p <= {ALPHA_OOP}: node-disjoint segments share a course) and how often "
                                 f"neighbouring segments' loadings on it also agree (sign-flip p <= {ALPHA_AGREE} "
                                 f"against node parts of a shared course): both are what naming out_of_plane needs "
                                 f"first, so on planar recordings 'both' counts false alarms; the median agreement "
                                 f"where the length test fires (about +1 for a swing, -1/2 for node parts). "
                                 f"Simulator: {a.frames} frames, {a.seeds} seeds per row. User path: rce simulate "
                                 f"--video then our tracker, 450 frames, the cases of 'python "
                                 f"benchmarks/bench_user_path.py --cache DIR --seeds 10 --first-seed 160 --effects "
                                 f"none,out_of_plane --renders clean,outdoor' (seeds no rule was written on). "
                                 f"Texture bed: real plant texture warped by known planar motion, H.264 crf 23, 300 "
                                 f"frames."),
                    columns=["source", "condition", "recordings", "length test fires", "both fire",
                             "agreement where the length test fires (median)"], rows=rows,
                    notes=[f"user path, the diagnosis' verdict ({r[0]}, {r[1]} renders): out_of_plane named {r[2]} "
                           f"without / with the signature; other verdicts with it: {r[3]}" for r in vrows])


if __name__ == "__main__":
    main()
