"""Measure the size and spectrum of each tracker-artifact family (:mod:`rce_gtsam.sim.artifacts`).

Two sources:

* **The project's tracker on rendered video with known truth** (ready-made cases, nothing is re-rendered):
  folders ``CASES/*_{clean,outdoor}_f450_s*/`` with ``sim/true_tracks.csv`` (truth; the outdoor render's camera
  shake included), ``sim/graph.json`` and ``run/tracks.csv`` (the tracker's output; ``visible`` 0 = lost).
  Error e = tracked - true, split along / across the branch (the true tangent). Per case:
  - lag: least squares e = -(tau_frames + tau_per_speed |v|) v over both channels (v: true velocity, px/frame);
  - speed_error: of the lag-corrected residual less its 3-s moving average (the drift), robust SD per speed
    decile, fitted SD^2 = s0^2 + (k |v|)^2 per channel (k = along_per_speed / across_per_speed); the same fit to
    the residual's white part (second differences) is printed beside it (on the outdoor renders the two agree
    within ~40 %: the speed error is mostly white; a plain, non-robust SD grows faster with speed, from rare
    larger errors that a Gaussian model does not carry);
  - slide: per node, slope of the along residual on the node's across displacement from frame 0 (px/px); its
    spread over nodes less the spread of the same slope against the time-reversed displacement (a null with the
    same autocorrelation): slope_sd = sqrt(max(0, var - var_null));
  - coloured_along: the along residual less its 3-s moving average (the drift) and less its white part: SD;
    spectral slope of the along residual between 1/128 and 1/10 cycles/frame (Welch);
  - drift: SD of the 3-s (90-frame) moving average of the residual, along and across;
  - gust_occlusion: share of lost frames per speed decile, fitted share = m (|v| / 1 px/frame)^g; mean burst.
* **The real plants' TAPIR tracks, no truth** (``/work/shared/data/plant_{1,2}``): the share of missing frames
  against the node's speed (gaps interpolated, 5-frame moving average) with the same fit and burst length;
  segment-stretch spectra (slope between 1/128 and 1/10 cycles/frame; a branch does not stretch, so stretch is
  along-branch tracking error plus foreshortening); along/across ratio of the raw tracks' 4th differences.

Which source sets each preset value (printed in the table and written into the presets file):
lag, speed_error, slide (an upper bound: no slide is detected), drift, coloured_along SD, gust_occlusion: the
project's tracker on the outdoor renders (median over cases; the clean renders are printed beside them; its
lost frames count as lost, as ``rce`` reads ``visible`` 0); coloured_along beta: the real plants' stretch
spectra (median of both plants). The real plants' missing-vs-speed is printed beside the tracker's.

Usage: python benchmarks/measure_artifacts.py [--cases /work/cache/up] [--plants /work/shared/data]
       [--write]  (write the fitted strengths into rce_gtsam/sim/artifact_presets.json as preset "measured")
"""

from __future__ import annotations

import argparse
import datetime
import glob
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MA = 90  # frames: the moving average that separates drift (slower) from coloured noise
BAND = (1 / 128, 1 / 10)  # cycles/frame: where spectral slopes are fitted


def to_array(df: pd.DataFrame, nodes, F: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, F, 2) positions (NaN where absent) and (N, F) visible flags from a tracks table."""
    row = {n: i for i, n in enumerate(nodes)}
    df = df[df.point_id.isin(row) & (df.frame < F)]
    xy = np.full((len(nodes), F, 2), np.nan)
    vis = np.zeros((len(nodes), F), bool)
    i, f = df.point_id.map(row).values, df.frame.values
    xy[i, f] = df[["x", "y"]].values
    vis[i, f] = df["visible"].values.astype(bool) if "visible" in df else True
    return xy, vis


def moving_average(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving average along the last axis (edges: shorter windows)."""
    k = np.ones(w)
    num = np.apply_along_axis(lambda r: np.convolve(r, k, "same"), -1, x)
    den = np.convolve(np.ones(x.shape[-1]), k, "same")
    return num / den


def white_sd(x: np.ndarray) -> np.ndarray:
    """Per-sample white-noise magnitude from second differences: |x_t - (x_{t-1} + x_{t+1}) / 2| / sqrt(1.5)."""
    d = np.full_like(x, np.nan)
    d[..., 1:-1] = (x[..., 1:-1] - 0.5 * (x[..., :-2] + x[..., 2:])) / np.sqrt(1.5)
    return d


def spectral_slope(x: np.ndarray) -> float:
    """-slope of log PSD against log f (beta of 1/f^beta) in BAND, from the mean Welch PSD of the rows of x."""
    F = x.shape[-1]
    f, P = signal.welch(x, nperseg=min(256, F), axis=-1, detrend="linear")
    P = np.nanmean(P.reshape(-1, P.shape[-1]), axis=0)
    m = (f >= BAND[0]) & (f <= BAND[1]) & (P > 0)
    return float(-np.polyfit(np.log(f[m]), np.log(P[m]), 1)[0])


def loss_fit(speed: np.ndarray, lost: np.ndarray) -> dict:
    """Share lost per speed decile and the fit share = m (speed / 1 px/frame)^g (weighted log-log LS)."""
    ok = np.isfinite(speed)
    edges = np.unique(np.quantile(speed[ok], np.linspace(0, 1, 11)))
    mid, share, n = [], [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = ok & (speed >= lo) & (speed <= hi)
        mid.append(float(np.median(speed[m])))
        share.append(float(lost[m].mean()))
        n.append(int(m.sum()))
    mid, share, n = np.array(mid), np.array(share), np.array(n)
    use = (share > 0) & (mid > 0)
    if use.sum() >= 3:
        w = np.sqrt(n[use] * share[use])
        g, logm = np.polyfit(np.log(mid[use]), np.log(share[use]), 1, w=w)
    else:
        g, logm = 0.0, np.log(max(lost[ok].mean(), 1e-6))
    runs = burst_lengths(lost)
    return {"miss_at_ref": float(np.exp(logm)), "speed_exponent": float(g), "share": float(lost[ok].mean()),
            "burst_frames": float(np.mean(runs)) if runs else 1.0, "deciles": [(round(float(a), 3), round(float(b), 4)) for a, b in zip(mid, share)]}


def burst_lengths(lost: np.ndarray) -> list[int]:
    out = []
    for row in lost:
        d = np.diff(np.r_[0, row.astype(int), 0])
        out += list(np.nonzero(d == -1)[0] - np.nonzero(d == 1)[0])
    return out


def measure_case(folder: Path) -> dict:
    """The per-family numbers of one rendered case (the project's tracker against the truth)."""
    from rce_gtsam.graph import load_graph
    from rce_gtsam.sim.artifacts import node_kinematics
    g = load_graph(folder / "sim" / "graph.json")
    tt = pd.read_csv(folder / "sim" / "true_tracks.csv")
    F = int(tt.frame.max()) + 1
    T, _ = to_array(tt, g.nodes, F)
    R, vis = to_array(pd.read_csv(folder / "run" / "tracks.csv"), g.nodes, F)
    tan, nrm, v, sp = node_kinematics(g, T)
    e = R - T
    ok = vis & np.isfinite(e[..., 0])
    ok[:, 0] = False
    # lag: e = -(tau0 + tau1 |v|) v, both channels
    X = np.stack([-v[ok].ravel(), -(sp[ok][:, None] * v[ok]).ravel()], axis=1)
    tau0, tau1 = np.linalg.lstsq(X, e[ok].ravel(), rcond=None)[0]
    r = e + (tau0 + tau1 * sp)[..., None] * v
    ra, rc = np.sum(r * tan, -1), np.sum(r * nrm, -1)
    # fill lost frames by interpolation for the filters (their values are not used as data)
    def filled(x):
        x = np.where(ok, x, np.nan)
        x[:, 0] = 0.0
        return pd.DataFrame(x.T).interpolate(limit_direction="both").values.T
    fa, fc = filled(ra), filled(rc)
    # cross-correlation of the error with the velocity at shifts -3..3 frames (both channels pooled): a lag
    # shows as a negative peak at shift 0 or later
    xc = {}
    for k in range(-3, 4):
        a_, b_ = (slice(max(k, 0), F + min(k, 0)), slice(max(-k, 0), F - max(k, 0)))
        m = ok[:, a_] & ok[:, b_]
        ee, vv = e[:, a_][m].ravel(), v[:, b_][m].ravel()
        xc[k] = float(np.dot(ee, vv) / np.sqrt(np.dot(ee, ee) * np.dot(vv, vv)))
    d4 = np.diff(np.where(ok[..., None], R, np.nan), n=4, axis=1)
    ta, tc = np.sum(d4 * tan[:, 2:-2], -1), np.sum(d4 * nrm[:, 2:-2], -1)
    g4 = np.isfinite(ta)
    out = {"case": folder.name, "render": "outdoor" if "_outdoor_" in folder.name else "clean",
           "xcorr_e_v": xc, "xcorr_peak": min(xc.values(), key=lambda c: -abs(c)),
           "along_over_across_d4": float(np.median(np.abs(ta[g4])) / np.median(np.abs(tc[g4]))),
           "tau_frames": float(tau0), "tau_per_speed": float(tau1),
           "sd_along_raw": float(np.nanstd(np.sum(e * tan, -1)[ok])),
           "sd_across_raw": float(np.nanstd(np.sum(e * nrm, -1)[ok]))}
    # speed error per speed decile, SD^2 = s0^2 + (k |v|)^2 (robust SDs), of two parts of the residual: its white
    # part (second differences) and everything faster than the drift (the residual less its 3-s moving average),
    # which keeps a speed error correlated over a few frames; the preset takes the second ("_per_speed"), the
    # white-part fit is printed beside it ("white_..._per_speed")
    for name, x in (("along", fa), ("across", fc)):
        for tag, part in (("white_", white_sd(x)), ("", x - moving_average(x, MA))):
            good = ok & np.isfinite(part)
            edges = np.quantile(sp[good], np.linspace(0, 1, 11))
            s2, v2 = [], []
            for lo, hi in zip(edges[:-1], edges[1:]):
                m = good & (sp >= lo) & (sp <= hi)
                s2.append((1.4826 * np.median(np.abs(part[m] - np.median(part[m])))) ** 2)
                v2.append(np.median(sp[m]) ** 2)
            A = np.stack([np.ones(len(v2)), v2], 1)
            c0, c1 = np.linalg.lstsq(A, np.array(s2), rcond=None)[0]
            out[f"{tag}{name}_per_speed"] = float(np.sqrt(max(c1, 0.0)))
            out[f"{tag or 'band_'}{name}_px"] = float(np.sqrt(max(c0, 0.0)))
    # slide: along residual vs across displacement from frame 0, against a time-reversed null
    d = np.sum((T - T[:, :1]) * nrm, -1)
    slopes, nulls = [], []
    for i in range(len(g.nodes)):
        m = ok[i]
        if m.sum() < 50 or np.std(d[i, m]) < 0.5:
            continue
        slopes.append(np.polyfit(d[i, m], ra[i, m], 1)[0])
        dn = d[i, ::-1]
        nulls.append(np.polyfit(dn[m], ra[i, m], 1)[0])
    out["slide_sd"] = float(np.sqrt(max(np.var(slopes) - np.var(nulls), 0.0))) if slopes else 0.0
    out["slide_sd_raw"] = float(np.std(slopes)) if slopes else 0.0
    out["slide_sd_null"] = float(np.std(nulls)) if nulls else 0.0
    # drift (slow) and coloured (faster, not white) along; drift across
    slow_a, slow_c = moving_average(fa, MA), moving_average(fc, MA)
    out["drift_along_px"] = float(np.sqrt(np.mean(slow_a[:, 1:] ** 2)))
    out["drift_across_px"] = float(np.sqrt(np.mean(slow_c[:, 1:] ** 2)))
    band = fa - slow_a
    wvar = np.nanmean(white_sd(fa)[ok] ** 2)
    out["coloured_sd_px"] = float(np.sqrt(max(np.var(band[ok]) - wvar, 0.0)))
    out["along_beta"] = spectral_slope(fa[:, 1:])
    out["across_beta"] = spectral_slope(fc[:, 1:])
    lost = ~vis
    lost[:, 0] = False
    out["loss"] = loss_fit(sp, lost)
    return out


def measure_plant(folder: Path) -> dict:
    """Visibility against motion, stretch spectra and along/across ratio of a real plant's TAPIR tracks."""
    from rce_gtsam.graph import load_graph
    from rce_gtsam.sim.artifacts import node_kinematics
    g = load_graph(folder / "branch_graph.json")
    df = pd.read_csv(folder / "tapir_tracks.csv")
    F = int(df.frame.max()) + 1
    xy, _ = to_array(df, g.nodes, F)
    lost = ~np.isfinite(xy[..., 0])
    filled = np.stack([pd.DataFrame(xy[..., k].T).interpolate(limit_direction="both").values.T
                       for k in range(2)], -1)
    sm = np.stack([moving_average(filled[..., k], 5) for k in range(2)], -1)
    tan, nrm, v, sp = node_kinematics(g, sm)
    row = {n: i for i, n in enumerate(g.nodes)}
    stretch = np.array([np.linalg.norm(filled[row[c]] - filled[row[p]], axis=-1) for p, c in g.edges])
    stretch -= np.median(stretch, axis=1, keepdims=True)
    d4 = np.diff(filled, n=4, axis=1)
    ta = np.sum(d4 * tan[:, 2:-2], -1)
    tc = np.sum(d4 * nrm[:, 2:-2], -1)
    good = ~(lost[:, :-4] | lost[:, 4:])
    mad = lambda x: 1.4826 * np.median(np.abs(x))  # noqa: E731
    return {"plant": folder.name, "frames": F, "loss": loss_fit(sp, lost),
            "stretch_beta": spectral_slope(stretch), "stretch_sd_px": float(np.std(stretch)),
            "along_over_across_d4": float(mad(ta[good]) / mad(tc[good])),
            "speed_median": float(np.median(sp)), "speed_p95": float(np.percentile(sp, 95))}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default="/work/cache/up")
    ap.add_argument("--plants", default="/work/shared/data")
    ap.add_argument("--write", action="store_true", help="write the fitted strengths into the presets file")
    a = ap.parse_args()
    cases = [Path(p).parent.parent for p in sorted(glob.glob(f"{a.cases}/*_f450_s*/run/tracks.csv"))
             if (Path(p).parent.parent / "sim" / "true_tracks.csv").exists()]
    rows = [measure_case(c) for c in cases]
    keys = ["tau_frames", "tau_per_speed", "along_per_speed", "across_per_speed", "white_along_per_speed",
            "white_across_per_speed", "white_along_px",
            "white_across_px", "slide_sd", "slide_sd_raw", "slide_sd_null", "coloured_sd_px", "along_beta", "across_beta",
            "drift_along_px", "drift_across_px", "sd_along_raw", "sd_across_raw", "along_over_across_d4",
            "xcorr_peak"]
    print("The project's tracker on rendered video against the truth (per case; px, frames, px/frame):")
    print(f"{'case':<26}" + "".join(f"{k[:13]:>14}" for k in keys) + f"{'lost share':>11}{'loss m':>8}{'loss g':>8}{'burst':>7}")
    for r in rows:
        print(f"{r['case']:<26}" + "".join(f"{r[k]:>14.3f}" for k in keys)
              + f"{r['loss']['share']:>11.3f}{r['loss']['miss_at_ref']:>8.3f}{r['loss']['speed_exponent']:>8.2f}{r['loss']['burst_frames']:>7.1f}")
    summary = {}
    for render in ("clean", "outdoor"):
        sel = [r for r in rows if r["render"] == render]
        if not sel:
            continue
        med = {k: float(np.median([r[k] for r in sel])) for k in keys}
        lo = {k: float(np.min([r[k] for r in sel])) for k in keys}
        hi = {k: float(np.max([r[k] for r in sel])) for k in keys}
        for k in ("miss_at_ref", "speed_exponent", "burst_frames", "share"):
            vals = [r["loss"][k] for r in sel]
            med[f"loss_{k}"], lo[f"loss_{k}"], hi[f"loss_{k}"] = (float(np.median(vals)), float(min(vals)),
                                                                  float(max(vals)))
        summary[render] = {"n": len(sel), "median": med, "min": lo, "max": hi}
        print(f"{render}: cross-correlation of error with velocity at shifts -3..3 frames (median over cases): "
              + ", ".join(f"{k:+d}: {np.median([r['xcorr_e_v'][k] for r in sel]):+.3f}" for k in range(-3, 4)))
        print(f"{render} renders, median over {len(sel)} cases [min - max]: "
              + "; ".join(f"{k} {med[k]:.3f} [{lo[k]:.3f}-{hi[k]:.3f}]" for k in med))
    plants = [measure_plant(Path(a.plants) / p) for p in ("plant_1", "plant_2") if (Path(a.plants) / p).exists()]
    print("\nReal plants' TAPIR tracks (no truth):")
    for p in plants:
        ls = p["loss"]
        print(f"  {p['plant']}: missing share {ls['share']:.3f}, fit share = {ls['miss_at_ref']:.4f} (|v| / 1 px/frame)"
              f"^{ls['speed_exponent']:.2f}, mean burst {ls['burst_frames']:.1f} frames; deciles (speed, share) "
              f"{ls['deciles']}; stretch SD {p['stretch_sd_px']:.2f} px (= along error SD {p['stretch_sd_px'] / np.sqrt(2):.2f} px per "
              f"node if it were all independent tracking error; out-of-plane foreshortening adds to it), stretch spectrum beta {p['stretch_beta']:.2f}; "
              f"along/across SD of 4th differences {p['along_over_across_d4']:.2f}; speed median "
              f"{p['speed_median']:.2f}, p95 {p['speed_p95']:.2f} px/frame")
    if "outdoor" not in summary or not plants:
        print("need outdoor cases and the plants to set the presets")
        return 1
    o = summary["outdoor"]["median"]
    pl = {k: float(np.median([p["loss"][k] for p in plants])) for k in ("miss_at_ref", "speed_exponent", "burst_frames")}
    beta = float(np.median([p["stretch_beta"] for p in plants]))
    src_o = f"the project's tracker on {summary['outdoor']['n']} outdoor renders (median over cases)"
    src_p = "the real plants' TAPIR tracks (median of plants 1 and 2)"
    preset = {
        "speed_error": {"along_per_speed": o["along_per_speed"], "across_per_speed": o["across_per_speed"],
                        "source": src_o},
        "lag": {"tau_frames": max(o["tau_frames"], 0.0), "tau_per_speed": max(o["tau_per_speed"], 0.0), "source": src_o},
        "gust_occlusion": {"miss_at_ref": o["loss_miss_at_ref"], "ref_speed": 1.0,
                           "speed_exponent": max(o["loss_speed_exponent"], 0.0), "burst_frames": o["loss_burst_frames"],
                           "source": f"{src_o}: its lost (visible 0) frames against the true speed; the real plants "
                                     f"(median miss_at_ref {pl['miss_at_ref']:.3g}, exponent {pl['speed_exponent']:.2f}, "
                                     f"burst {pl['burst_frames']:.1f} frames) lose fewer frames"},
        "slide": {"slope_sd": o["slide_sd_raw"],
                  "source": f"{src_o}: an upper bound, the raw spread of the per-node slopes (its excess over the "
                            f"time-reversed null, {o['slide_sd']:.4f}, is within the null's own spread "
                            f"{o['slide_sd_null']:.4f}: no slide detected)"},
        "coloured_along": {"sd_px": o["coloured_sd_px"], "beta": beta,
                           "source": f"sd_px: {src_o}; beta: {src_p} (segment-stretch spectra)"},
        "drift": {"along_px": o["drift_along_px"], "across_px": o["drift_across_px"], "time_s": 5.0,
                  "source": f"{src_o}; time_s assumed (a 15-s record cannot measure a slower correlation time)"},
    }
    print("\nPreset 'measured' (1x):")
    for fam, q in preset.items():
        print(f"  {fam:<15} " + ", ".join(f"{k}={v:.4g}" for k, v in q.items() if k != "source") + f"   <- {q['source']}")
    if a.write:
        from rce_gtsam.sim.artifacts import PRESETS_PATH
        doc = {"format": "rce_gtsam artifact presets v1", "presets": {"measured": {
            "provenance": {"command": "python benchmarks/measure_artifacts.py --write",
                           "date": datetime.date.today().isoformat(),
                           "cases": [r["case"] for r in rows], "plants": [p["plant"] for p in plants],
                           "outdoor_summary": summary["outdoor"], "clean_summary": summary.get("clean"),
                           "plants_summary": [{k: v for k, v in p.items()} for p in plants]},
            **preset}}}
        tmp = PRESETS_PATH.with_suffix(".tmp")
        tmp.write_text(json.dumps(doc, indent=1, default=float) + "\n")
        tmp.replace(PRESETS_PATH)
        print(f"wrote {PRESETS_PATH}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
