"""The built-in tracker and kappa on real texture with known motion (``rce_gtsam.sim.texture_bed``).

For each seed and condition (effect-free, and with a delay): plant 2's frame 0, overlays inpainted, warped by the
simulator's motion on plant 2's chain at the real plant's scale (tip excursion ``--tip-px``, default 60 px), with
motion blur, sensor noise, flicker and H.264; videos and truth are cached in ``--cache`` (default
/work/cache/texture, else the temp folder). Scores:

* tracker error against the truth (px): median and p90 of the points marked visible;
* visible share overall and in the fastest 30 % of frames (frames ranked by the fastest node's true speed);
* kappa (``rce_gtsam.analyze``, default preset) against the true kappa: log-RMSE, Spearman, and the share of true
  kappa inside the 95 % CI, for our tracks and for the true tracks through the same pipeline;
* the root's distance from where it is (it is fixed), and the tip's visible share and error where marked lost;
* the physical floor: the bend-angle noise sqrt(2..6) e / L (rad) a tracker error of e px gives on the median
  segment of L px, against the RMS of the bending to measure.

``--baseline REV`` also runs the default tracker (``rce_gtsam/track/lk*.py``) of that revision on the same videos
(before/after). ``--crf`` renders the bed at other x264 compressions; ``--bound`` adds the Cramér-Rao bound of the
node positions (white noise of the measured level) and kappa at it; ``--oracle`` an estimator that knows every
frame's noise-free appearance, whose error is what the compression itself displaces (``texture_bound.py``).
Needs ``../shared/data/plant_2`` beside the repository.

Usage: python benchmarks/bench_texture_bed.py [--seeds 0,1,2,3,4] [--frames 300] [--baseline REV] [--n-boot 100]
       [--crf 0,12,18,23] [--bound] [--oracle] [--record NAME]
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import spearmanr

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
#: plant 2's folder: ``../shared/data/plant_2`` beside the repository, or $RCE_PLANT2_DIR (a git worktree elsewhere)
PLANT = Path(os.environ.get("RCE_PLANT2_DIR", ROOT.parent / "shared" / "data" / "plant_2"))


def default_cache() -> Path:
    c = Path("/work/cache/texture")
    try:
        c.mkdir(parents=True, exist_ok=True)
        return c
    except OSError:
        return Path(tempfile.gettempdir()) / "rce_texture_bed"


def bed_case(seed: int, effects: tuple, n_frames: int, tip_px: float, cache: Path, settings=None):
    """(bed, clean frame, mp4 path), rendered once and cached. ``settings``: the bed's ``RenderSettings`` (None:
    the default; others are cached under a tag of their rigid band, ``inner_px``/``outer_px``, their crf, or
    "perfect": :meth:`~rce_gtsam.sim.texture_bed.RenderSettings.perfect`)."""
    from rce_gtsam.sim.texture_bed import RenderSettings, clean_first_frame, make_bed, write_bed_video

    settings = settings or RenderSettings()
    tag = f"v3_s{seed}_{'-'.join(effects) or 'none'}_f{n_frames}_tip{tip_px:g}"
    if (settings.inner_px, settings.outer_px) != (RenderSettings.inner_px, RenderSettings.outer_px):
        tag += f"_in{settings.inner_px:g}_out{settings.outer_px:g}"
    if settings.is_perfect:
        tag += "_perfect"
    elif settings.crf != RenderSettings.crf:
        tag += f"_crf{settings.crf}"
    plain = replace(settings, inner_px=RenderSettings.inner_px, outer_px=RenderSettings.outer_px)
    if not (plain.is_perfect or replace(plain, crf=RenderSettings.crf) == RenderSettings()):
        raise ValueError(f"bed_case caches by rigid band, crf and perfect rendering only, got {settings}")
    cache.mkdir(parents=True, exist_ok=True)
    path, meta = cache / f"{tag}.mp4", cache / f"{tag}.pkl"
    cf = clean_first_frame(PLANT)
    if meta.is_file() and path.is_file():
        bed = pickle.loads(meta.read_bytes())
    else:
        bed = make_bed(cf.points, cf.graph, n_frames, seed, effects, tip_excursion_px=tip_px)
        write_bed_video(bed, cf.rgb, cf.points, path, settings=settings)
        meta.write_bytes(pickle.dumps(bed))
    return bed, cf, path


def kappa_scores(tracks, graph, bed, n_boot: int):
    """(log-RMSE, Spearman, share of true kappa inside the CI) of kappa from ``tracks`` (a Tracks object)."""
    import rce_gtsam

    r = rce_gtsam.analyze(tracks, graph, preset="default", n_boot=n_boot, seed=0)
    est = np.array([r.kappa[e] for e in r.response.edges])
    tru = np.array([bed.kappa_true[e] for e in r.response.edges])
    lr = float(np.sqrt(np.mean(np.log(est / tru) ** 2)))
    inside = float(np.mean((tru >= r.ci.low) & (tru <= r.ci.high))) if r.ci is not None else np.nan
    return lr, float(spearmanr(est, tru)[0]), inside


def score(res, bed, graph, n_boot: int) -> dict:
    from rce_gtsam.tracks import load_tracks

    truth = bed.true_xy
    err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
    vis = res.visible
    speed = np.zeros(truth.shape[1])
    speed[1:] = np.hypot(*np.diff(truth, axis=1).transpose(2, 0, 1)).max(axis=0)
    fast = speed >= np.quantile(speed, 0.7)
    with tempfile.TemporaryDirectory() as tmp:
        tracks = load_tracks(res.write_csv(Path(tmp) / "t.csv"), graph)
    lr, rho, inside = kappa_scores(tracks, graph, bed, n_boot)
    root = graph.root
    tip = bed.edges[-1][1]
    lost_tip = ~vis[tip]
    z = (err / res.sigma_px)[vis]
    return {"median": float(np.median(err[vis])), "p90": float(np.percentile(err[vis], 90)),
            "max": float(err[vis].max()), "visible": float(vis.mean()), "visible_fast": float(vis[:, fast].mean()),
            "kappa_logrmse": lr, "kappa_rho": rho, "kappa_in_ci": inside,
            "root_median_px": float(np.median(err[root])), "tip_visible": float(vis[tip].mean()),
            "tip_err_lost": float(np.median(err[tip][lost_tip])) if lost_tip.any() else np.nan,
            "z_p90": float(np.percentile(z, 90))}


def true_rotations_tracker():
    """An ``LKTracker`` whose refinement pass poses each node's articulated template with its segments' true
    rotations (from the bed's true positions, ``TrueRotations(true_xy)``) instead of those its first-pass matches
    imply: everything else, the first pass and the search included, as the default tracker's."""
    from rce_gtsam.track import LKTracker

    class TrueRotations(LKTracker):
        def __init__(self, true_xy, *a, **k):
            super().__init__(*a, **k)
            self.true_xy, self._frame = true_xy, 0

        def _refine(self, gray0, gray, q0, est, vis, fb_max, first_done=None):
            self._frame += 1  # the refinement pass runs once per frame after the first
            return super()._refine(gray0, gray, q0, est, vis, fb_max, first_done)

        def _refine_thetas(self, i, est, vis):
            t = self.true_xy[:, self._frame]  # every segment seen, at its true place
            return super()._refine_thetas(i, t, np.ones(len(t), bool))

    return TrueRotations


def truth_plus(bed, graph, E: np.ndarray, sigma_px: np.ndarray, source: str):
    """Tracks of the truth plus the error ``E`` (P, F, 2) px, each node reported with its sigma ``sigma_px`` (P,) px
    (at least 0.05 px, the tracker's floor)."""
    from rce_gtsam.tracks import Tracks

    nodes = list(graph.nodes)
    sig = np.broadcast_to(np.maximum(sigma_px, 0.05)[:, None], bed.true_xy.shape[:2])
    return Tracks(node_ids=np.array(nodes), xy=(bed.true_xy + E)[nodes], sigma_px=np.array(sig[nodes]),
                  source=source)


def bound_kappa(bed, graph, per_axis_px: np.ndarray, n_boot: int, draws: int = 3) -> float:
    """Mean kappa log-RMSE of the true tracks plus white noise of ``per_axis_px`` (P,) px per axis per node (its
    sigma reported with it), over ``draws`` seeded draws: kappa from a tracker at the Cramér-Rao bound."""
    out = []
    for k in range(draws):
        rng = np.random.default_rng([bed.seed, k, 71])
        E = rng.standard_normal(bed.true_xy.shape) * per_axis_px[:, None, None]
        out.append(kappa_scores(truth_plus(bed, graph, E, per_axis_px, "bound"), graph, bed, n_boot)[0])
    return float(np.mean(out))


def oracle_scores(bed, graph, E: np.ndarray, n_boot: int) -> tuple:
    """(median |error| px, kappa log-RMSE, Spearman, truth in CI) of the oracle's tracks, the truth plus ``E`` (P, F, 2)
    px (:func:`texture_bound.oracle_tracks`), each node's sigma its RMS error per axis (at least 0.05 px)."""
    t = truth_plus(bed, graph, E, np.sqrt(np.mean(E ** 2, axis=(1, 2))), "oracle")
    free = [n for n in graph.nodes if n != graph.root]
    return (float(np.median(np.hypot(*E[free].transpose(2, 0, 1)))), *kappa_scores(t, graph, bed, n_boot))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--tip-px", type=float, default=60.0)
    ap.add_argument("--n-boot", type=int, default=100, help="bootstrap resamples of each analysis")
    ap.add_argument("--conditions", default="none,delay", help="comma list: none and/or effect names")
    ap.add_argument("--baseline", default=None, help="git revision of the default tracker (rce_gtsam/track/lk*.py) to run as well")
    ap.add_argument("--crf", default=None, metavar="N[,N]",
                    help="x264 constant rate factors to render the bed at (default: the bed's, 23), e.g. 0,12,18,23")
    ap.add_argument("--bound", action="store_true",
                    help="also the Cramér-Rao bound of the node positions on each video (texture_bound.py) and kappa "
                         "of the true tracks plus white noise at that bound")
    ap.add_argument("--oracle", action="store_true",
                    help="also an oracle that knows every frame's noise-free appearance (texture_bound.oracle_tracks): "
                         "its error is what the compression itself displaces, and kappa from its tracks")
    ap.add_argument("--perfect", action="store_true",
                    help="also the bed rendered perfectly (no noise, flicker or blur; lossless): the tracker's own "
                         "deterministic error (RenderSettings.perfect)")
    ap.add_argument("--true-rotations", action="store_true",
                    help="also our tracker with the true segment rotations posing its templates in the refinement "
                         "pass (TrueRotations): what its rotation estimate costs")
    ap.add_argument("--record", default=None, metavar="NAME",
                    help="save the per-crf summary as docs/validation/NAME.json (with --crf)")
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    if not (PLANT / "annotated_nodes.mp4").is_file():
        raise SystemExit(f"plant 2 footage not found at {PLANT}")
    from rce_gtsam.sim.texture_bed import RenderSettings, angle_floor_deg
    from rce_gtsam.track import LKTracker, open_video
    from rce_gtsam.tracks import Tracks

    cache = args.cache or default_cache()
    trackers = {"current": lambda bed: LKTracker()}
    tmp = tempfile.TemporaryDirectory()
    if args.baseline:
        from bench_track import baseline_tracker
        base_cls = baseline_tracker(args.baseline, Path(tmp.name))
        trackers = {"baseline": lambda bed: base_cls(), **trackers}
    if args.true_rotations:
        trackers["true-rot"] = lambda bed: true_rotations_tracker()(bed.true_xy)
    seeds = [int(s) for s in args.seeds.split(",")]
    conds = [() if c == "none" else (c,) for c in args.conditions.split(",")]
    crfs = [int(c) for c in args.crf.split(",")] if args.crf else [RenderSettings.crf]
    # (label, settings) of each rendering: the crfs asked for, then the perfect one
    renders = [(crf, RenderSettings(crf=crf)) for crf in crfs] + (
        [("perfect", RenderSettings().perfect())] if args.perfect else [])
    crfs = [label for label, _ in renders]
    rows = {(name, crf, c): [] for name in trackers for crf in crfs for c in conds}
    truth_rows = {c: [] for c in conds}
    bounds = {crf: [] for crf in crfs}  # (bound median px per axis, noise grey levels, kappa log-RMSE at the bound)
    sizes = {crf: [] for crf in crfs}  # MB per 10 s of video
    oracles = {crf: [] for crf in crfs}  # (median |error| px, kappa log-RMSE, Spearman, truth in CI)
    floor = []
    print(f"texture bed: plant 2 frame 0 inpainted, {args.frames} frames, tip excursion {args.tip_px:g} px, "
          f"seeds {seeds}, H.264 crf {crfs}; kappa: default preset, n_boot {args.n_boot}; cache {cache}")
    hdr = (f"  {'tracker':8s} {'crf':>3s} {'cond':6s} {'seed':>4s} {'med':>5s} {'p90':>5s} {'max':>5s} {'vis':>5s} "
           f"{'visfast':>7s} {'logRMSE':>7s} {'rho':>5s} {'inCI':>5s} {'root':>5s} {'tipvis':>6s} {'tiplost':>7s} "
           f"{'z90':>5s}" + (f" {'bound':>6s} {'noise':>5s} {'bndRMSE':>7s}" if args.bound else ""))
    print(hdr)
    for crf, settings in renders:
        for c in conds:
            for seed in seeds:
                bed, cf, path = bed_case(seed, c, args.frames, args.tip_px, cache, settings)
                graph = cf.graph
                nodes = list(graph.nodes)
                if crf == crfs[0]:
                    true_tr = Tracks(node_ids=np.array(nodes), xy=bed.true_xy[nodes], source="truth")
                    truth_rows[c].append(kappa_scores(true_tr, graph, bed, args.n_boot))
                    L = np.array([np.hypot(*(cf.points[ch] - cf.points[p])) for p, ch in bed.edges])
                    floor.append((np.median(L), float(np.sqrt(np.mean(bed.response_deg ** 2)))))
                sizes[crf].append(path.stat().st_size / 1e6 * 300.0 / args.frames)
                extra = ""
                if args.bound:
                    from texture_bound import node_bound
                    per, noise = node_bound(bed, cf.rgb, cf.points, path, settings)
                    b = (float(np.median(per[per > 0])), noise, bound_kappa(bed, graph, per, args.n_boot))
                    bounds[crf].append(b)
                    extra = f" {b[0]:6.3f} {b[1]:5.2f} {b[2]:7.2f}"
                if args.oracle:
                    from texture_bound import oracle_tracks
                    o = oracle_scores(bed, graph, oracle_tracks(bed, cf.rgb, cf.points, path, settings), args.n_boot)
                    oracles[crf].append(o)
                    extra += f"  oracle {o[0]:.3f} px, kappa {o[1]:.2f}"
                for name, make in trackers.items():
                    with open_video(path) as src:
                        res = make(bed).track(src, cf.points, graph)
                    s = score(res, bed, graph, args.n_boot)
                    rows[(name, crf, c)].append(s)
                    print(f"  {name:8s} {crf!s:>3s} {'-'.join(c) or 'none':6s} {seed:4d} {s['median']:5.2f} "
                          f"{s['p90']:5.2f} {s['max']:5.1f} {s['visible']:5.3f} {s['visible_fast']:7.3f} "
                          f"{s['kappa_logrmse']:7.2f} {s['kappa_rho']:5.2f} {s['kappa_in_ci']:5.2f} "
                          f"{s['root_median_px']:5.2f} {s['tip_visible']:6.2f} {s['tip_err_lost']:7.2f} "
                          f"{s['z_p90']:5.1f}{extra}", flush=True)
    print("summary (mean over seeds):")
    for (name, crf, c), rs in rows.items():
        with warnings.catch_warnings():  # a tip never marked lost has no error-where-lost (NaN in every seed)
            warnings.simplefilter("ignore", RuntimeWarning)
            m = {k: np.nanmean([r[k] for r in rs]) for k in rs[0]}
        print(f"  {name:8s} {'-'.join(c) or 'none':6s}" + (f" crf {crf}" if len(crfs) > 1 else "")
              + f": error median {m['median']:.2f} / p90 {m['p90']:.2f} px; "
              f"visible {100 * m['visible']:.1f} %, fastest 30 % {100 * m['visible_fast']:.1f} %; kappa log-RMSE "
              f"{m['kappa_logrmse']:.2f}, Spearman {m['kappa_rho']:.2f}, truth in CI {100 * m['kappa_in_ci']:.0f} %; "
              f"root {m['root_median_px']:.2f} px; tip visible {100 * m['tip_visible']:.0f} %")
    for c, rs in truth_rows.items():
        a = np.array(rs)
        print(f"  true tracks {'-'.join(c) or 'none':6s}: kappa log-RMSE {a[:, 0].mean():.2f}, Spearman "
              f"{a[:, 1].mean():.2f}, truth in CI {100 * a[:, 2].mean():.0f} %")
    L, bend = np.median([f[0] for f in floor]), np.mean([f[1] for f in floor])
    floor_crf = [label for label, st in renders if not st.is_perfect][-1]
    for name in trackers:
        # median error, px, on the last compressed rendering (not the perfect one)
        e = float(np.mean([r["median"] for c in conds for r in rows[(name, floor_crf, c)]]))
        lo, hi = angle_floor_deg(e, L)
        print(f"  physical floor ({name}): error e = {e:.2f} px on the median segment L = {L:.1f} px gives "
              f"{lo:.2f}-{hi:.2f} deg of angle noise against a bending RMS of {bend:.2f} deg "
              f"(noise/signal {lo / bend:.2f}-{hi / bend:.2f})")
    table = []
    for crf, name in [(crf, name) for crf in crfs for name in trackers if name != "baseline"]:
        rs = [r for c in conds for r in rows[(name, crf, c)]]
        m = {k: float(np.mean([r[k] for r in rs])) for k in ("median", "p90", "kappa_logrmse", "kappa_rho",
                                                               "kappa_in_ci", "visible")}
        label = crf if name == "current" else f"{crf}, true rotations"
        row = [label, len(rs), round(float(np.mean(sizes[crf])), 2), round(m["median"], 3), round(m["p90"], 3),
               round(100 * m["visible"], 1), round(m["kappa_logrmse"], 3), round(m["kappa_rho"], 2),
               round(100 * m["kappa_in_ci"], 1)]
        if args.bound and name == "current":
            b = np.array(bounds[crf])
            row += [round(float(b[:, 1].mean()), 2), round(float(b[:, 0].mean()), 3), round(float(b[:, 2].mean()), 3)]
            print(f"  crf {crf}: noise {b[:, 1].mean():.2f} grey levels; Cramér-Rao bound {b[:, 0].mean():.3f} px per "
                  f"axis (median node); kappa log-RMSE at the bound {b[:, 2].mean():.2f} (ours "
                  f"{m['kappa_logrmse']:.2f})")
        if args.oracle and name == "current":
            o = np.array(oracles[crf])
            row += [round(float(o[:, 0].mean()), 3), round(float(o[:, 1].mean()), 3),
                    round(float(100 * o[:, 3].mean()), 1)]
            print(f"  crf {crf}: the oracle (knows each frame's noise-free appearance): error median "
                  f"{o[:, 0].mean():.3f} px, kappa log-RMSE {o[:, 1].mean():.2f}, Spearman {o[:, 2].mean():.2f}, "
                  f"truth in CI {100 * o[:, 3].mean():.0f} % (ours {m['kappa_logrmse']:.2f})")
        table.append(row)
    if args.record:
        from record import save_record
        a = np.array([r for rs in truth_rows.values() for r in rs])
        cols = ["x264 crf", "cases", "video (MB per 10 s)", "error median (px)", "error p90 (px)", "visible (%)",
                "kappa log-RMSE", "Spearman", "truth in 95 % CI (%)"]
        if args.bound:
            cols += ["noise (grey levels RMS)", "Cramér-Rao bound (px per axis, median node)",
                     "kappa log-RMSE at the bound"]
        if args.oracle:
            cols += ["oracle error median (px)", "kappa log-RMSE, oracle", "truth in 95 % CI, oracle (%)"]
        title = ("Texture bed: what compression costs the tracker and kappa, and what any tracker could reach"
                 if not args.perfect else "Texture bed: our tracker's own error, on perfectly rendered frames")
        save_record(args.record, title=title,
                    command=f"python benchmarks/bench_texture_bed.py --seeds {args.seeds} --conditions "
                            f"{args.conditions} --crf {','.join(str(c) for c in crfs if c != 'perfect')}"
                            + (" --bound" if args.bound else "") + (" --oracle" if args.oracle else "")
                            + (" --perfect" if args.perfect else "")
                            + (" --true-rotations" if args.true_rotations else "")
                            + f" --record {args.record}",
                    description=("Plant 2's frame 0 (overlays inpainted) warped by the simulator's motion at the real "
                                 f"plant's scale (tip {args.tip_px:g} px, {args.frames} frames), blur, sensor noise "
                                 "2 grey levels, flicker, then H.264 at each crf; our tracker (default) and kappa "
                                 "(default preset) against the truth, mean over seeds and conditions."
                                 + (" The bound: per "
                                    "node the Cramér-Rao bound of its position from the stem pixels of the noise-free "
                                    "render, with white noise of the level measured in the decoded video "
                                    "(benchmarks/texture_bound.py); kappa at the bound: the true tracks plus white "
                                    "noise of that size." if args.bound else "")
                                 + (" The oracle: an estimator that knows every frame's noise-free appearance at the "
                                    "true pose and fits the decoded frame's stem pixels with it, moved by the bed's "
                                    "articulated model (texture_bound.oracle_tracks): its error is what the noise and "
                                    "the compression displace; kappa from the truth plus that error." if args.oracle
                                    else "")
                                 + (" 'perfect': the same bed with no sensor noise, flicker or blur, H.264 lossless "
                                    "(RenderSettings.perfect): what our tracker still gets wrong there is its own, "
                                    "deterministic error." if args.perfect else "")
                                 + (" 'true rotations': our tracker with the true segment rotations posing its "
                                    "templates in its refinement pass (TrueRotations in this script): what its "
                                    "rotation estimate costs." if args.true_rotations else "")),
                    columns=cols, rows=table,
                    notes=[f"true tracks: kappa log-RMSE {a[:, 0].mean():.3f}, truth in CI "
                           f"{100 * a[:, 2].mean():.0f} %",
                           f"the bed's bending: {bend:.2f} deg RMS per joint on segments of median {L:.1f} px"])
    tmp.cleanup()


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
