"""The validation record of bench_depth3d.py (docs/validation/depth3d.json, per-seed values in
benchmarks/results/depth3d_seeds.json and depth3d_oracles.json), written with :func:`record.save_record`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from record import save_record

RESULTS = Path(__file__).resolve().parent / "results"

#: (column of a rendered-recording row, what it is)
RENDERED = [("2d_video", "rce run video.mp4 (2-D)"),
            ("2d_rec", "rce run recording.db3, the 2-D fit of its tracks"),
            ("3d", "rce run recording.db3, kappa from the 3-D angles"),
            ("3d_in", "the same, in-plane 3-D bends only"),
            ("3d+len@off", "re-fit from that run's tracks.csv and depths (no inextensibility)"),
            ("3d+len@0.01", "the same with the inextensibility factor (sigma 1 % of L)"),
            ("3d bp_in", "the same (no inextensibility), in-plane bends from the pixels on the branch plane"),
            ("3d z-exact", "re-fit from that run's tracks.csv with the true depth (rounded to mm)"),
            ("ceiling", "a perfect 2-D tracker (kappa_true_image)")]
#: (column of an oracle row, what it is)
ORACLES = [("true3d", "oracle: the true 3-D positions"),
           ("px0+z", "oracle: true pixels (0.1 px) + D435i depth noise"),
           ("px0+z +len", "the same with the inextensibility factor"),
           ("px0+z bp_in", "the same (no inextensibility), in-plane bends from the pixels on the branch plane"),
           ("px0 2d", "oracle: the 2-D pipeline on those 0.1 px pixels"),
           ("pxN+z0", "oracle: tracker-noise pixels + exact depth"),
           ("pxN+z", "oracle: tracker-noise pixels + D435i depth noise"),
           ("pxN+z +len", "the same with the inextensibility factor"),
           ("pxN+z bp_in", "the same (no inextensibility), in-plane bends from the pixels on the branch plane"),
           ("pxN 2d", "oracle: the 2-D pipeline on the tracker-noise pixels")]


def _med(rows, key):
    v = np.array([r[key] for r in rows if key in r], float)
    return (float(np.median(v)), len(v)) if v.size else (float("nan"), 0)


def write(rows: list[dict], orows: list[dict], frames: int, command: str) -> Path:
    """Save the record from the rendered rows (without errors) and the oracle rows."""
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "depth3d_seeds.json").write_text(json.dumps(rows, indent=1) + "\n")
    (RESULTS / "depth3d_oracles.json").write_text(json.dumps(orows, indent=1) + "\n")
    table = []
    for src, spec in ((rows, RENDERED), (orows, ORACLES)):
        for key, label in spec:
            m, n = _med(src, key)
            if n:
                table.append([label, n, round(m, 3)])
    notes = []
    if rows and all("2d_video" in r and "3d" in r for r in rows):
        ratio = np.array([r["3d"] / r["2d_video"] for r in rows])
        notes.append(f"rce run recording.db3 (3-D) against video.mp4 (2-D): median ratio {np.median(ratio):.2f} over "
                     f"{len(rows)} seeds, <= 0.5 in {int(np.sum(ratio <= 0.5))}: the goal of 0.5x is "
                     + ("reached." if np.median(ratio) <= 0.5 else "not reached."))
    o = {k: _med(orows, k)[0] for k, _ in ORACLES}
    if orows:
        def cmp(a, b):
            return "better" if o[a] < o[b] else "worse"
        notes.append(
            f"The ceiling ({len(orows)} seeds, no video): the fit itself {o['true3d']:.3f}. With the tracker-noise "
            f"model's pixels (~0.8 px) even the exact depth gives {o['pxN+z0']:.3f} against {o['pxN 2d']:.3f} for the "
            f"2-D pipeline on the same pixels (and the noisy depth {o['pxN+z']:.3f}, not explained here): at that "
            f"pixel error no depth handling halves the 2-D error.")
        r3, rl = o["px0+z"] / o["px0 2d"], o["px0+z +len"] / o["px0 2d"]
        per = np.array([r["px0+z +len"] / r["px0 2d"] for r in orows])
        pr_len, n_len = float(np.median(per)), int(np.sum(per <= 0.5))
        n_better = int(sum(r["px0+z +len"] < r["px0+z"] for r in orows))
        notes.append(
            f"With a 0.1 px tracker (no gross failures) the 2-D pipeline gives {o['px0 2d']:.3f} (its out-of-plane "
            f"bias: the perfect 2-D tracker's {_med(orows, 'image')[0]:.3f}), the 3-D angles {o['px0+z']:.3f} ({r3:.2f}x) and, "
            f"with the inextensibility factor, {o['px0+z +len']:.3f} ({rl:.2f}x): there the length factor is what "
            f"brings the 3-D kappa near half the 2-D error (per seed: median ratio {pr_len:.2f}, <= 0.5 in "
            f"{n_len} of {len(orows)}; better than without the factor in {n_better}). With the ~0.8 px tracker-noise pixels it gives "
            f"{o['pxN+z +len']:.3f} against {o['pxN+z']:.3f} without (the length turns the pixel error along a segment "
            f"into depth error, x L/dz = 2-4), so it is off by default. The in-plane bends from the pixels moved "
            f"onto the branch plane (depth only fits the plane) give {o['px0+z bp_in']:.3f} (0.1 px) and "
            f"{o['pxN+z bp_in']:.3f} (~0.8 px).")
    if rows:
        pm, pr, pg = (_med(rows, k)[0] for k in ("px_err_median", "px_err_rms", "px_gross_pct"))
        zm, zd, zs = (_med(rows, k)[0] for k in ("z_err_median", "z_err_mad", "z_sigma_median"))
        notes.append(f"The rendered runs' tracker: median pixel error {pm:.2f} px, but RMS {pr:.1f} px ({pg:.1f} % of "
                     f"node-frames off by > 1 px; medians over seeds); with the true depth its tracks give "
                     f"{_med(rows, '3d z-exact')[0]:.3f}: the pixel error, not the depth, bounds the 3-D kappa.")
        notes.append(f"The read depth (stem surface) is {-zm:.1f} mm nearer than the stem's axis and scatters "
                     f"{zd:.1f} mm (1.4826 MAD) about it, while the reader claims {zs:.1f} mm (its D435 model, "
                     f"focal 430 px, against the simulator's 674 px).")
        s3, s2 = _med(rows, "smooth_3d_s")[0], _med(rows, "smooth_2d_s")[0]
        sl = _med(rows, "smooth_3d_s+len@0.01")[0]
        notes.append("The previous record (2-D video 0.342, 3-D 0.309) came from older code; per seed the values moved "
                     "by up to +-0.5 (the tracker's gross failures make single seeds noisy).")
        notes.append(f"The 3-D smoother costs {s3:.1f} s (with the inextensibility factor {sl:.1f} s) against "
                     f"{s2:.2f} s for the 2-D one (median, loaded 2-core machine).")
    return save_record(
        "depth3d", title="Kappa from the RealSense depth stream against kappa from the 2-D video (out-of-plane "
                         "swing), and its ceiling", command=command,
        description=(f"rce simulate --effect out_of_plane --depth (share 0.5, tilt 30 deg, {frames} frames): the same "
                     "recording through rce run as video.mp4 (2-D) and as recording.db3 (depth per node, the 3-D "
                     "GTSAM smoother, 3-D turning angles), and the oracles of benchmarks/depth3d_oracles.py (no video: "
                     "the simulator's truth with chosen errors). Kappa log-RMSE against the 3-D truth, median over "
                     "seeds; per-seed values in benchmarks/results/depth3d_seeds.json and depth3d_oracles.json."),
        columns=["kappa from", "seeds", "log-RMSE vs the 3-D truth (median)"], rows=table, notes=notes)
