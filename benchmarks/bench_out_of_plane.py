"""Out-of-plane swing named from 2-D tracks: the length channel's test, the diagnosis' verdicts, the held-out error.

Recordings: the 3-D simulator (``rce simulate --effect out_of_plane``: :mod:`rce_gtsam.sim.three_d`, ``share`` =
the out-of-plane share of the wind, default 0.5, the branch plane tilted 30 deg, a pinhole projection, then the
default tracker noise and the tracker-artifact family); planar = the 2-D simulator (no out_of_plane effect) -> ``analyze(preset="default", n_boot=0)`` -> the diagnosis as
``rce diagnose`` runs it (:func:`rce_gtsam.diagnosis.io.diagnose_result`).

Printed:
1. calibration of the length test (what naming out_of_plane needs first: p <= ALPHA_OOP) on planar recordings with
   every tracker-artifact family at each scale, and on a planar branch whose plane is tilted (share 0, tilt 30:
   the lengths move with z; not a swing, but motion out of the image plane), and its power on swinging ones;
2. the whole diagnosis on swinging recordings (default share and 2x) and planar ones: how often out_of_plane is the
   verdict, the held-out RMSE change of the bend model with it (%, the candidate's improvement), and kappa
   log-RMSE against the 3-D truth (rank-1, and the extended model's) and against the image-plane truth;
3. with ``--real DIR``: both real plants (DIR/plant_1, DIR/plant_2): the length test, the verdict and the variance
   budget before/after (the unexplained share with the named effect's residuals).

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_out_of_plane.py [--seeds 20] [--frames 450]
       [--families none,slide,gust_occlusion,speed_error,lag,coloured_along,drift] [--scales 1,2]
       [--diagnose-seeds 20] [--real /work/shared/data]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def recording(seed: int, frames: int, share: float, tilt: float | None, family: str | None = None,
              scale: float = 1.0):
    """(simulation, 3-D truth or None, analysis): ``share`` 0 and ``tilt`` None: the planar 2-D simulator."""
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.artifacts import ArtifactConfig
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    from rce_gtsam.sim.three_d import Scene3D

    art = ArtifactConfig(families=(family,), scale=scale) if family else ArtifactConfig()
    effects = ("out_of_plane",) if share > 0 else ()
    scene = None if tilt is None else Scene3D(tilt_deg=tilt)
    sim = simulate(SimulationConfig(seed=seed, n_frames=frames, artifacts=art, effects=effects,
                                    effect_strength={"out_of_plane": share} if share > 0 else None, scene3d=scene))
    return sim, sim.three_d, analyze(sim.tracks, sim.graph, preset="default", n_boot=0)


def length_p(res) -> float:
    from rce_gtsam.effects.out_of_plane import OutOfPlane
    test = OutOfPlane.for_analysis(res).length_test(seed=0)
    return 1.0 if test is None else test.p


def log_rmse(k: np.ndarray, truth: np.ndarray) -> float:
    d = np.log(np.abs(k)) - np.log(truth)
    d -= d.mean()  # both relative (geometric mean 1)
    return float(np.sqrt(np.mean(d * d)))


def calibration(a) -> None:
    from rce_gtsam.diagnosis.length_channel import ALPHA_OOP
    print(f"\n1. length test, p <= {ALPHA_OOP} (the first condition for naming out_of_plane); "
          f"{a.seeds} seeds x {a.frames} frames")
    cases = [("swing share 0.5, tilt 30", 0.5, 30.0, None, 1.0), ("planar tilted 30, no swing", 0.0, 30.0, None, 1.0)]
    cases += [(f"swing share 0.5, tilt 30, {fam} 2x", 0.5, 30.0, fam, 2.0) for fam in ("slide", "gust_occlusion")
              if fam in a.families]
    for fam in a.families:
        for k in ((1.0,) if fam == "none" else a.scales):
            cases.append((f"planar, {fam}" + ("" if fam == "none" else f" {k:g}x"), 0.0, None,
                          None if fam == "none" else fam, k))
    for name, share, tilt, fam, k in cases:
        t = time.perf_counter()
        ps = np.array([length_p(recording(s, a.frames, share, tilt, fam, k)[2]) for s in range(a.seeds)])
        print(f"  {name:34s} {int(np.sum(ps <= ALPHA_OOP)):3d}/{len(ps)}   (p <= 0.05: {int(np.sum(ps <= 0.05))}; "
              f"median p {np.median(ps):.3f}; {time.perf_counter() - t:.0f} s)", flush=True)


def diagnosis(a) -> None:
    from rce_gtsam.diagnosis.io import diagnose_result
    from rce_gtsam.effects.out_of_plane import OutOfPlane

    print(f"\n2. the diagnosis (rce diagnose's path); {a.diagnose_seeds} seeds x {a.frames} frames")
    conditions = (("swing share 0.5, tilt 30", 0.5, 30.0), ("swing share 1.0, tilt 30", 1.0, 30.0),
                  ("planar (2-D simulator)", 0.0, None))
    for name, share, tilt in (c for c in conditions if not a.conditions or c[1] in a.conditions):
        t = time.perf_counter()
        named, imps, imps_named, verdicts, lgain, lgain_named = 0, [], [], {}, [], []
        lr_base, lr_ext, lr_img = [], [], []
        for s in range(a.diagnose_seeds):
            sim, truth, res = recording(s, a.frames, share, tilt)
            d = diagnose_result(res)
            verdicts[d.verdict] = verdicts.get(d.verdict, 0) + 1
            c = d.candidate(OutOfPlane.name)
            imps.append(c.improvement_pct)
            lgain.append(c.extra.get("length_heldout_gain_pct", float("nan")))
            if d.verdict == OutOfPlane.name:
                named += 1
                imps_named.append(c.improvement_pct)
                lgain_named.append(lgain[-1])
            row = {b.edge: i for i, b in enumerate(sim.graph.bends)}
            idx = [row[tuple(e)] for e in res.response.edges]
            k3 = (truth.kappa_3d if truth is not None else np.array([sim.kappa_true[b.edge] for b in sim.graph.bends]))[idx]
            ki = truth.kappa_image[idx] if truth is not None else k3
            lr_base.append(log_rmse(d.baseline.kappa, k3))
            lr_ext.append(log_rmse(c.fit.kappa, k3))
            lr_img.append(log_rmse(d.baseline.kappa, ki))
        print(f"  {name:28s} out_of_plane named {named}/{a.diagnose_seeds}; verdicts {verdicts}; held-out RMSE "
              f"change with the term: median {np.median(imps):+.2f} % (when named: mean "
              f"{np.mean(imps_named) if imps_named else float('nan'):+.2f} %, min "
              f"{np.min(imps_named) if imps_named else float('nan'):+.2f} %); held-out length error change with the "
              f"term: median {-np.nanmedian(lgain):+.1f} % (when named: median "
              f"{-np.nanmedian(lgain_named) if lgain_named else float('nan'):+.1f} %, range "
              f"{-np.nanmax(lgain_named) if lgain_named else float('nan'):+.1f} to "
              f"{-np.nanmin(lgain_named) if lgain_named else float('nan'):+.1f} %); kappa log-RMSE vs 3-D truth: rank-1 "
              f"{np.median(lr_base):.3f}, with the term {np.median(lr_ext):.3f}; rank-1 vs image-plane truth "
              f"{np.nanmedian(lr_img):.3f} (medians; {time.perf_counter() - t:.0f} s)", flush=True)


def real(a) -> None:
    from rce_gtsam.diagnosis.io import diagnose_result
    from rce_gtsam.effects.out_of_plane import OutOfPlane
    from rce_gtsam.pipeline import analyze

    print("\n3. real plants (default preset; budget in deg^2, mean over scored segment-frames)")
    rows = []
    for plant in ("plant_1", "plant_2"):
        d0 = Path(a.real) / plant
        if not (d0 / "tapir_tracks.csv").exists():
            print(f"  {plant}: {d0 / 'tapir_tracks.csv'} not found, skipped")
            continue
        t = time.perf_counter()
        res = analyze(d0 / "tapir_tracks.csv", d0 / "branch_graph.json", preset="default", n_boot=0)
        d = diagnose_result(res)
        c = d.candidate(OutOfPlane.name)
        x = c.extra
        b = d.budget.as_dict() if d.budget is not None else {}
        after = budget_after(d, c) if d.budget is not None else None
        agree = (f"neighbouring segments' agreement {x.get('length_agreement', float('nan')):+.2f} "
                 f"(p {x.get('length_agreement_p', float('nan')):.3g})")
        print(f"  {plant}: length test p {x.get('p')}, statistic {x.get('length_statistic', float('nan')):.0f} "
              f"(null median {x.get('length_null_median', float('nan')):.0f}), same-sign share "
              f"{x.get('length_same_sign_share', float('nan')):.2f}, tip growth "
              f"{x.get('length_tip_growth', float('nan')):+.2f}, {agree}; held-out RMSE change with the term "
              f"{c.improvement_pct:+.2f} %; held-out length error change "
              f"{-x.get('length_heldout_gain_pct', float('nan')):+.1f} %; verdict {d.verdict}, status {d.status}",
              flush=True)
        if b:
            print(f"    budget before: total {b['total']:.2f}, rank-1 explains {b['rank1']:.2f}, noise floor "
                  f"{b['noise_floor']:.2f}, unexplained {b['unexplained']:.2f} +- {b['unexplained_se']:.2f} "
                  f"({b['status']})")
        if after is not None:
            print(f"    budget with out_of_plane's residuals: unexplained {after['unexplained']:.2f} +- "
                  f"{after['unexplained_se']:.2f} ({after['status']}); {time.perf_counter() - t:.0f} s")
        without = (f"; without the segments of node {x.get('length_carrying_node')} (which carries "
                   f"{100 * x.get('length_carrying_share', float('nan')):.0f} % of the length course): p "
                   f"{x.get('length_p_without_node', float('nan')):.3g}, held-out length error "
                   f"{-x.get('length_heldout_gain_without_node_pct', float('nan')):+.1f} %")
        print("   " + without[2:])
        nf = d.noise_floor.as_dict() if d.noise_floor is not None else {}
        rows.append([f"{plant.replace('_', ' ')} (TAPIR tracks)",
                     f"length test p {x.get('p')}; {agree}",
                     d.verdict if d.verdict is not None and d.verdict == OutOfPlane.name else "not named",
                     f"held-out length error {-x.get('length_heldout_gain_pct', float('nan')):+.1f} %{without}"
                     + (f"; unexplained {b['unexplained']:.2f} +/- {b['unexplained_se']:.2f} deg^2 before, "
                        f"{after['unexplained']:.2f} with the term ({b['status']}); noise floor "
                        f"{b['noise_floor']:.2f} of {b['total']:.2f} deg^2"
                        + (f" (node error {nf['nodewise_sigma_px']:.2f} px)" if nf.get('nodewise_sigma_px') else "")
                        if b and after is not None else "")])
    if getattr(a, "record_real", False) and rows:
        update_plant_rows(rows)


def update_plant_rows(rows: list[list]) -> None:
    """Replace the real plants' rows of the out_of_plane record (docs/validation/out_of_plane.json), the rest kept,
    through record.save_record (schema check, atomic write)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from record import load_record, save_record
    rec = load_record("out_of_plane")
    kept = [r for r in rec["rows"] if not str(r[0]).startswith("plant ")]
    save_record("out_of_plane", title=rec["title"], command=rec["command"], columns=rec["columns"],
                rows=kept + rows, description=rec["description"], notes=rec.get("notes"))


def budget_after(d, c) -> dict:
    """The variance budget with the out_of_plane candidate's fit added (as the diagnosis makes it for a verdict)."""
    from rce_gtsam.diagnosis.budget import variance_budget
    base = d.baseline
    out = variance_budget(base.Y, base.residuals, base.n_params, d.noise_floor,
                          {c.effect: (c.fit.residuals, c.fit.n_params)}, d.edge_labels, base_kappa=base.kappa)
    return out.as_dict()


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--diagnose-seeds", type=int, default=20)
    p.add_argument("--frames", type=int, default=450)
    p.add_argument("--families", default="none,slide,gust_occlusion,speed_error,lag,coloured_along,drift")
    p.add_argument("--scales", default="1,2")
    p.add_argument("--real", default=None, help="folder with plant_1/ and plant_2/ (tapir_tracks.csv, branch_graph.json)")
    p.add_argument("--skip", default="", help="comma list of parts to skip: calibration, diagnosis")
    p.add_argument("--record-real", action="store_true", help="with --real: write the plants' rows into the "
                                                              "out_of_plane record (the other rows kept)")
    p.add_argument("--conditions", default="", help="comma list of swing shares the diagnosis part runs (0 = planar; "
                                                    "default: 0.5, 1 and planar)")
    a = p.parse_args(argv)
    a.families = [f for f in a.families.split(",") if f]
    a.conditions = [float(c) for c in a.conditions.split(",") if c]
    a.scales = [float(s) for s in a.scales.split(",") if s]
    skip = set(a.skip.split(","))
    warnings.simplefilter("ignore", RuntimeWarning)
    if "calibration" not in skip:
        calibration(a)
    if "diagnosis" not in skip:
        diagnosis(a)
    if a.real:
        real(a)


if __name__ == "__main__":
    main()
