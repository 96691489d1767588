"""Tables and files of an :class:`~rce_gtsam.pipeline.AnalysisResult`.

Output folder (all CSV, one header row):

* ``compliance_summary.csv`` — one row per edge, ordered by root distance: parent, child, depth, zone,
  root_distance_px, rest_length_px, kappa, kappa_ci_low, kappa_ci_high, uncertainty (U_e = CI width /
  kappa), direction (+1/-1, sign of the fitted gain), relative_stiffness (1/kappa), n_frames (frames
  with a usable bend response), fit_rmse_deg, fit_r2, bend_rms_deg (filtered RMS of delta), bend_snr
  (bending variance / its noise floor), z_var_seen, floor_log_rmse (the kappa log-RMSE the tracker's error alone
  allows the segment, :mod:`rce_gtsam.kappa_floor`) and quality (``ok`` or the reasons kappa should not be trusted,
  :mod:`rce_gtsam.quality`). The root edge has no bend, so its kappa columns are empty.
* ``excitation.csv`` — frame, z (degrees).
* ``bending.csv`` — grandparent, joint, child, frame, angle_deg, delta_deg, inlier (0/1), angle_var_deg2.
* ``smoothed_tracks.csv`` — point_id, frame, x, y (pixels, every frame), observed (0/1), cov_xx,
  cov_xy, cov_yy (marginal covariance, px^2).
* ``report.json`` — inputs, preset, convergence, smoothing metrics, timings.

The folder is written through a temporary sibling directory that replaces the previous folder by renames
(files of the previous folder that this run does not write are carried over), so a failure or an
interruption leaves the previous results as they were and no half-written files.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd

from .fileio import temp_dir_beside
from .version import __version__
from .jsonutil import jsonable as _jsonable
from .quality import assess_quality, assess_reported_quality, quality_report


def compliance_summary(result) -> pd.DataFrame:
    """One row per edge of the graph, ordered by root distance (see module docstring)."""
    g, geo, resp, fit = result.graph, result.geometry, result.response, result.fit
    row_of = {e: i for i, e in enumerate(resp.edges)}
    pred = fit.predict()
    bend_rms = dict(zip([b.edge for b in result.bending.bends], result.smoothing.bend_rms_smoothed_deg))
    U = result.uncertainty
    quality = assess_quality(result)
    from .tracks import dropped_edges, lost_nodes
    dropped = set(dropped_edges(g, lost_nodes(result.tracks)))
    floor = getattr(result, "kappa_floor", None)
    records = []
    for e in sorted(g.edges, key=lambda e: (geo.root_distance_px[e[1]], e[0], e[1])):
        p, c = e
        rec = {"parent": p, "child": c, "depth": g.depth[c], "zone": geo.zone[c],
               "root_distance_px": geo.root_distance_px[c], "rest_length_px": geo.rest_length_px[e]}
        i = row_of.get(e)
        if i is None:
            rec.update(kappa=np.nan, kappa_ci_low=np.nan, kappa_ci_high=np.nan, uncertainty=np.nan,
                       direction=np.nan, relative_stiffness=np.nan, n_frames=0, fit_rmse_deg=np.nan,
                       fit_r2=np.nan, bend_rms_deg=np.nan, bend_snr=np.nan, z_var_seen=np.nan,
                       floor_log_rmse=np.nan, quality="tracking_lost" if e in dropped else "")
        else:
            y = resp.Y[i]
            ok = np.isfinite(y)
            res = y[ok] - pred[i, ok]
            ss_tot = float(np.sum((y[ok] - y[ok].mean()) ** 2)) if ok.any() else np.nan
            k = float(fit.kappa[i])
            rec.update(
                kappa=k,
                kappa_ci_low=float(result.ci.low[i]) if result.ci is not None else np.nan,
                kappa_ci_high=float(result.ci.high[i]) if result.ci is not None else np.nan,
                uncertainty=float(U[i]) if U is not None else np.nan,
                direction=int(fit.direction[i]),
                relative_stiffness=1.0 / k if k > 1e-9 else np.nan,
                n_frames=int(ok.sum()),
                fit_rmse_deg=float(np.sqrt(np.mean(res**2))) if ok.any() else np.nan,
                fit_r2=float(1 - np.sum(res**2) / ss_tot) if ss_tot > 1e-6 else np.nan,
                bend_rms_deg=float(bend_rms[e]),
                bend_snr=quality[e].snr,
                z_var_seen=quality[e].z_var_seen,
                floor_log_rmse=float(floor.log_rmse_per_segment[i]) if floor is not None else np.nan,
                quality=quality[e].quality,
            )
        records.append(rec)
    df = pd.DataFrame.from_records(records)
    if getattr(result, "kappa_choice", None) is not None:
        from .kappa_report import add_to_summary
        reported = assess_reported_quality(result, quality) if result.kappa_choice.fitted else None
        df = add_to_summary(df, result.kappa_choice,
                            None if reported is None else {e: q.quality for e, q in reported.items()})
    return df


def excitation_table(result) -> pd.DataFrame:
    return pd.DataFrame({"frame": result.response.frames, "z": result.fit.z})


def bending_table(result) -> pd.DataFrame:
    b = result.bending
    rows, frames = np.nonzero(np.isfinite(b.angle_deg))
    trip = np.array([bend.nodes for bend in b.bends], dtype=int)
    var = b.variance_deg2[rows, frames] if b.variance_deg2 is not None else np.full(rows.size, np.nan)
    return pd.DataFrame({"grandparent": trip[rows, 0], "joint": trip[rows, 1], "child": trip[rows, 2],
                         "frame": frames, "angle_deg": b.angle_deg[rows, frames],
                         "delta_deg": b.delta_deg[rows, frames], "inlier": b.inlier[rows, frames].astype(int),
                         "angle_var_deg2": var})


def smoothed_table(result) -> pd.DataFrame:
    s = result.smoothed
    N, F, _ = s.tracks.xy.shape
    n, f = np.meshgrid(np.arange(N), np.arange(F), indexing="ij")
    n, f = n.ravel(), f.ravel()
    cov = s.cov if s.cov is not None else np.full((N, F, 2, 2), np.nan)
    return pd.DataFrame({"point_id": s.tracks.node_ids[n], "frame": f,
                         "x": s.tracks.xy[n, f, 0], "y": s.tracks.xy[n, f, 1],
                         "observed": s.observed[n, f].astype(int),
                         "cov_xx": cov[n, f, 0, 0], "cov_xy": cov[n, f, 0, 1], "cov_yy": cov[n, f, 1, 1]})


def report_dict(result) -> dict:
    """The machine-readable report (``report.json``)."""
    fit, ci, sm = result.fit, result.ci, result.smoothed.report
    qualities = assess_quality(result)  # the rank-1 verdicts, read by the quality section and the kappa to report
    return _jsonable({
        "rce_gtsam_version": __version__,
        "inputs": {**result.inputs, "n_nodes": result.tracks.n_nodes, "n_frames": result.tracks.n_frames,
                   "n_observations": int(result.tracks.observed.sum()), "root": result.graph.root,
                   "n_edges": len(result.graph.edges), "n_bends": len(result.bending.bends)},
        "preset": {"name": result.preset.name, **{k: asdict(v) for k, v in
                                                  (("smoother", result.preset.smoother),
                                                   ("bending", result.preset.bending),
                                                   ("compliance", result.preset.compliance))}},
        "convergence": {
            "smoother": asdict(sm),
            "compliance": {"iterations": fit.iterations, "converged": fit.converged,
                           "max_log_kappa_change": fit.max_log_change},
            "bootstrap": None if ci is None else {"n_boot": ci.n_boot, "block_length": ci.block_length,
                                                  "seed": ci.seed, "method": ci.method,
                                                  "effective_samples": ci.effective_samples,
                                                  "width_factor": ci.width_factor,
                                                  "time_split": (result.time_split.as_dict()
                                                                 if getattr(result, "time_split", None) else None)},
        },
        "smoothing_metrics": result.smoothing.as_dict(),
        "excitation_rms_deg": float(np.sqrt(np.mean(fit.z**2))),
        "timings_s": result.timings_s,
        "quality": quality_report(result, qualities),
        "kappa_floor": None if getattr(result, "kappa_floor", None) is None else result.kappa_floor.as_dict(),
        **({"effects": result.effects_report()} if getattr(result, "effects", None) else {}),
        **({"kappa_to_report": _kappa_to_report(result, qualities)}
           if getattr(result, "kappa_choice", None) is not None else {}),
    })


def _kappa_to_report(result, rank1: dict) -> dict:
    """report.json's ``kappa_to_report``: which κ to read and why, and, for the κ of a model with a named effect,
    each segment's quality (:func:`rce_gtsam.quality.assess_reported_quality` from the rank-1 verdicts ``rank1``)
    and how many are ok and informative."""
    out = result.kappa_choice.as_dict()
    if result.kappa_choice.fitted:
        q = assess_reported_quality(result, rank1)
        out["quality"] = {f"{p}->{c}": v.quality for (p, c), v in q.items()}
        out["n_ok"] = sum(v.ok for v in q.values())
        out["n_informative"] = sum(v.informative is True for v in q.values())
    return out


CSV_CHUNK_ROWS = 20_000  # rows formatted at a time by write_csv (bounded memory; the bytes do not depend on it)


def write_csv(df: pd.DataFrame, path: str | Path) -> None:
    """``df.to_csv(path, index=False)``: the same bytes, in half the time for the big all-numeric tables
    (integer and float columns, NaN written empty; floats as Python's shortest round-trip repr, which is
    what pandas writes through numpy). Other tables go through pandas. Rows are formatted ``CSV_CHUNK_ROWS``
    at a time: the text of a whole 50,000-frame table at once (a Python string per value) took the peak memory
    of ``rce analyze`` on 50,000 frames x 20 nodes from 1.27 to 2.06 GB."""
    simple = df.shape[1] >= 2 and all(isinstance(c, str) and c.isidentifier() for c in df.columns)
    if not simple or not all(dt.kind in "iuf" for dt in df.dtypes):
        df.to_csv(path, index=False)
        return
    arrays = [(df[name].to_numpy(), df[name].dtype.kind == "f") for name in df.columns]
    with open(path, "w", encoding="utf-8") as f:
        f.write(",".join(df.columns) + "\n")
        for start in range(0, len(df), CSV_CHUNK_ROWS):
            cols = []
            for values, is_float in arrays:
                chunk = values[start:start + CSV_CHUNK_ROWS].tolist()
                cols.append(["" if v != v else repr(v) for v in chunk] if is_float else [str(v) for v in chunk])
            f.write("\n".join(map(",".join, zip(*cols))) + "\n")


def write_outputs(result, out_dir: str | Path, extra_writers=()) -> dict[str, Path]:
    """Write every output file into ``out_dir`` without leaving half-written files behind.

    ``extra_writers``: callables ``writer(result, tmp_dir) -> dict[name, Path]`` (figures, recordings)
    that run inside the same temporary folder.
    """
    out_dir = Path(out_dir)
    tmp = temp_dir_beside(out_dir)
    try:
        tables = {"compliance_summary.csv": compliance_summary(result),
                  "excitation.csv": excitation_table(result),
                  "bending.csv": bending_table(result),
                  "smoothed_tracks.csv": smoothed_table(result)}
        for name, df in tables.items():
            write_csv(df, tmp / name)
        (tmp / "report.json").write_text(json.dumps(report_dict(result), indent=2) + "\n")
        for writer in extra_writers:
            writer(result, tmp)
        written = sorted(p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file())
        if out_dir.exists():
            _keep_other_files(out_dir, tmp, set(written))
        swap_folder(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {str(rel): out_dir / rel for rel in written}


def _keep_other_files(old: Path, new: Path, replaced: set[Path]) -> None:
    """Carry the files of ``old`` that this run does not rewrite (a recording, notes) into ``new``: hard
    links where the file system allows, copies elsewhere."""
    for p in old.rglob("*"):
        rel = p.relative_to(old)
        if not p.is_file() or rel in replaced:
            continue
        (new / rel).parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(p, new / rel)
        except OSError:
            shutil.copy2(p, new / rel)


def swap_folder(tmp: Path, out_dir: Path) -> None:
    """Put the finished folder ``tmp`` at ``out_dir`` with renames only: the previous ``out_dir`` is moved
    aside, ``tmp`` moved in, the old one deleted. An interruption before the swap leaves the previous
    folder untouched; between the two renames (microseconds) it sits complete beside it as
    ``.NAME.old-*``."""
    if not out_dir.exists():
        os.replace(tmp, out_dir)
        return
    aside = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.old-", dir=out_dir.parent))
    aside.rmdir()
    os.replace(out_dir, aside)
    try:
        os.replace(tmp, out_dir)
    except BaseException:
        os.replace(aside, out_dir)
        raise
    shutil.rmtree(aside, ignore_errors=True)
