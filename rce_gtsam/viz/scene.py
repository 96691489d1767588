"""What the viewer draws, independent of where it came from.

:class:`AnalysisView` gathers the arrays the Rerun recording needs (tracks, covariances, the response
matrix and the rank-1 prediction, kappa and its CI, the predicted skeleton). It is built either from an
in-memory :class:`~rce_gtsam.pipeline.AnalysisResult` (:meth:`AnalysisView.from_result`) or from an output
folder written by ``rce analyze`` (:meth:`AnalysisView.from_folder`), so ``rce view DIR`` and
``rce analyze --rerun`` draw the same thing.

Predicted skeleton (:func:`predicted_skeleton`): forward kinematics of the model's bending angles. Each
segment keeps its rest length; the root node and the heading of every root edge follow the measured
(smoothed) positions, so a rigid sway of the whole plant is not counted as misfit; every other segment's
heading is its parent segment's heading plus the bend's rest turning angle plus the model's predicted
deviation. Where the predicted skeleton leaves the measured one, the model fails there and then.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from ..graph import BranchGraph


@dataclass(frozen=True, eq=False)
class AnalysisView:
    """Arrays for drawing one analysis. Pixels, degrees, frames.

    node_ids (N,); graph; xy (N, F, 2) smoothed positions at every frame; observed (N, F) bool;
    cov (N, F, 2, 2) marginal covariance px^2 or None; raw_xy (N, F, 2) input tracks (NaN = unobserved) or None.
    edges: the E edges (joint, child) of the response rows, ordered by root distance; frames (T,) video
    frame of each response column; Y (E, T) observed response (NaN = missing/outlier); pred (E, T) the
    rank-1 prediction; variance (E, T) angle variance deg^2 or None; kappa, ci_low, ci_high (E,);
    zone (E,) str; root_distance_px (E,); z (T,) excitation in degrees.
    predicted_xy (N, F, 2): predicted skeleton (NaN outside ``frames``). response: "signed" | "abs".
    title: a short description (input file or "simulation"). floor_log_rmse (E,): what the tracker's error alone
    allows each segment's kappa (log-RMSE, :mod:`rce_gtsam.kappa_floor`) or None; floor_text: the summary's "what
    limits kappa" lines ("" without them). report_column: the ``compliance_summary.csv`` column of the κ to report
    ("kappa", or ``kappa_<effect>`` after a verdict whose model was fitted, :mod:`rce_gtsam.kappa_report`);
    kappa_report, ci_low_report, ci_high_report (E,): that κ and its 95 % CI, or None when it is the rank-1 κ.
    """

    node_ids: np.ndarray
    graph: BranchGraph
    xy: np.ndarray
    observed: np.ndarray
    cov: np.ndarray | None
    raw_xy: np.ndarray | None
    edges: list[tuple[int, int]]
    frames: np.ndarray
    Y: np.ndarray
    pred: np.ndarray
    variance: np.ndarray | None
    kappa: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    zone: np.ndarray
    root_distance_px: np.ndarray
    z: np.ndarray
    predicted_xy: np.ndarray
    response: str
    title: str = ""
    floor_log_rmse: np.ndarray | None = None
    floor_text: str = ""
    report_column: str = "kappa"
    kappa_report: np.ndarray | None = None
    ci_low_report: np.ndarray | None = None
    ci_high_report: np.ndarray | None = None

    @property
    def residual(self) -> np.ndarray:
        """(E, T) observed minus predicted response, degrees (NaN where not observed)."""
        return self.Y - self.pred

    @property
    def n_frames(self) -> int:
        return int(self.xy.shape[1])

    def edge_name(self, e: tuple[int, int]) -> str:
        """Entity-path-safe name of an edge, e.g. ``edge_8_7``."""
        return f"edge_{e[0]}_{e[1]}"

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_result(cls, result) -> "AnalysisView":
        """From an :class:`~rce_gtsam.pipeline.AnalysisResult`."""
        resp, fit, b = result.response, result.fit, result.bending
        E = len(resp.edges)
        ci_low = result.ci.low if result.ci is not None else np.full(E, np.nan)
        ci_high = result.ci.high if result.ci is not None else np.full(E, np.nan)
        pred = fit.predict()
        rest = b.rest_deg[resp.bend_rows]
        delta_obs = b.delta_deg[resp.bend_rows][:, resp.frames]
        xy = result.smoothed.tracks.xy
        node_ids = result.tracks.node_ids
        pxy = predicted_skeleton(result.graph, node_ids, xy, resp.frames, resp.edges, pred, rest,
                                 result.geometry.rest_length_px, signed=b.signed, delta_obs=delta_obs)
        return cls(node_ids=node_ids, graph=result.graph, xy=xy, observed=result.smoothed.observed,
                   cov=result.smoothed.cov, raw_xy=result.tracks.xy, edges=list(resp.edges),
                   frames=resp.frames, Y=resp.Y, pred=pred, variance=resp.variance, kappa=fit.kappa,
                   ci_low=ci_low, ci_high=ci_high,
                   zone=np.array([result.geometry.zone[c] for _, c in resp.edges]),
                   root_distance_px=resp.root_distance_px, z=fit.z, predicted_xy=pxy,
                   response=result.preset.compliance.response,
                   title=str(result.inputs.get("tracks", result.tracks.source)),
                   **_floor_fields(getattr(result, "kappa_floor", None)), **_reported_fields(result))

    @classmethod
    def from_folder(cls, folder: str | Path, tracks: str | Path | None = None) -> "AnalysisView":
        """From an output folder of ``rce analyze`` (compliance_summary.csv, excitation.csv, bending.csv,
        smoothed_tracks.csv, report.json). ``tracks``: the input tracks CSV for the raw points (default:
        the path recorded in report.json, when it still exists)."""
        folder = Path(folder)
        need = ["compliance_summary.csv", "excitation.csv", "bending.csv", "smoothed_tracks.csv", "report.json"]
        missing = [n for n in need if not (folder / n).is_file()]
        if missing:
            raise InputError(folder, f"not an analysis output folder: missing {missing} "
                                     "(write one with `rce analyze TRACKS GRAPH --out DIR`)")
        report = json.loads((folder / "report.json").read_text())
        summ = pd.read_csv(folder / "compliance_summary.csv")
        exc = pd.read_csv(folder / "excitation.csv")
        bend = pd.read_csv(folder / "bending.csv")
        sm = pd.read_csv(folder / "smoothed_tracks.csv")
        preset = report.get("preset", {})
        response = preset.get("compliance", {}).get("response", "abs")
        signed = bool(preset.get("bending", {}).get("signed", False))

        pairs = [(int(p), int(c)) for p, c in zip(summ.parent, summ.child)]
        children = {c for _, c in pairs}
        roots = sorted({p for p, _ in pairs} - children)
        graph = BranchGraph.from_edges(roots[0] if roots else report.get("inputs", {}).get("root"),
                                       [list(e) for e in pairs], source=str(folder / "compliance_summary.csv"))
        node_ids = np.array(sorted(sm.point_id.unique()), dtype=int)
        F = int(sm.frame.max()) + 1
        row = {int(n): i for i, n in enumerate(node_ids)}
        ni = sm.point_id.map(row).to_numpy()
        fi = sm.frame.to_numpy()
        xy = np.full((len(node_ids), F, 2), np.nan)
        xy[ni, fi, 0], xy[ni, fi, 1] = sm.x.to_numpy(), sm.y.to_numpy()
        observed = np.zeros((len(node_ids), F), bool)
        observed[ni, fi] = sm.observed.to_numpy().astype(bool)
        cov = None
        if {"cov_xx", "cov_xy", "cov_yy"} <= set(sm.columns) and sm.cov_xx.notna().any():
            cov = np.full((len(node_ids), F, 2, 2), np.nan)
            cov[ni, fi, 0, 0] = sm.cov_xx.to_numpy()
            cov[ni, fi, 0, 1] = cov[ni, fi, 1, 0] = sm.cov_xy.to_numpy()
            cov[ni, fi, 1, 1] = sm.cov_yy.to_numpy()

        fitted = summ[summ.kappa.notna()]
        edges = [(int(p), int(c)) for p, c in zip(fitted.parent, fitted.child)]
        frames = exc.frame.to_numpy().astype(int)
        z = exc.z.to_numpy(float)
        col = {int(f): k for k, f in enumerate(frames)}
        E, T = len(edges), len(frames)
        delta = np.full((E, T), np.nan)
        inlier = np.zeros((E, T), bool)
        var = np.full((E, T), np.nan)
        rest = np.full(E, np.nan)
        erow = {e: i for i, e in enumerate(edges)}
        for (j, c), g in bend.groupby(["joint", "child"]):
            i = erow.get((int(j), int(c)))
            if i is None:
                continue
            cols = g.frame.map(col)
            ok = cols.notna().to_numpy()
            k = cols[ok].to_numpy().astype(int)
            delta[i, k] = g.delta_deg.to_numpy()[ok]
            inlier[i, k] = g.inlier.to_numpy()[ok].astype(bool)
            if "angle_var_deg2" in g:
                var[i, k] = g.angle_var_deg2.to_numpy()[ok]
            rest[i] = float(np.nanmedian(g.angle_deg.to_numpy() - g.delta_deg.to_numpy()))
        Y = np.abs(delta) if response == "abs" else delta.copy()
        Y[~inlier] = np.nan
        var[~inlier] = np.nan
        kappa = fitted.kappa.to_numpy(float)
        direction = fitted.direction.to_numpy(float) if "direction" in fitted else np.ones(E)
        pred = (kappa * np.nan_to_num(direction, nan=1.0))[:, None] * z[None, :]
        rest_len = {(int(p), int(c)): float(L) for p, c, L in zip(summ.parent, summ.child, summ.rest_length_px)}
        pxy = predicted_skeleton(graph, node_ids, xy, frames, edges, pred, rest, rest_len, signed=signed,
                                 delta_obs=delta)
        raw = None
        tracks_path = Path(tracks) if tracks is not None else None
        if tracks_path is None and report.get("inputs", {}).get("tracks"):
            cand = Path(report["inputs"]["tracks"])
            tracks_path = cand if cand.is_file() else None
        if tracks_path is not None:
            from ..tracks import load_tracks
            t = load_tracks(tracks_path, graph)
            raw = np.full_like(xy, np.nan)
            trow = {int(n): i for i, n in enumerate(t.node_ids)}
            FF = min(F, t.xy.shape[1])
            for n, i in row.items():
                raw[i, :FF] = t.xy[trow[n], :FF]
        return cls(node_ids=node_ids, graph=graph, xy=xy, observed=observed, cov=cov, raw_xy=raw, edges=edges,
                   frames=frames, Y=Y, pred=pred, variance=None if np.isnan(var).all() else var, kappa=kappa,
                   ci_low=fitted.kappa_ci_low.to_numpy(float), ci_high=fitted.kappa_ci_high.to_numpy(float),
                   zone=fitted.zone.to_numpy().astype(str), root_distance_px=fitted.root_distance_px.to_numpy(float),
                   z=z, predicted_xy=pxy, response=response, title=str(folder),
                   **_floor_fields(report.get("kappa_floor"),
                                   fitted.floor_log_rmse.to_numpy(float) if "floor_log_rmse" in fitted else None),
                   **_reported_columns(fitted))


def _reported_fields(result) -> dict:
    """The view's κ-to-report fields from ``result.kappa_choice`` (none unless an effect's κ was fitted)."""
    choice = getattr(result, "kappa_choice", None)
    if choice is None or not choice.fitted:
        return {}
    kappa, low, high = choice.aligned(result.response.edges)
    return {"report_column": choice.column, "kappa_report": kappa, "ci_low_report": low, "ci_high_report": high}


def _reported_columns(fitted) -> dict:
    """The view's κ-to-report fields from compliance_summary.csv's rows (``report`` names the column)."""
    col = str(fitted["report"].iloc[0]) if "report" in fitted and len(fitted) else "kappa"
    if col == "kappa" or col not in fitted:
        return {}
    get = lambda c: fitted[c].to_numpy(float) if c in fitted else np.full(len(fitted), np.nan)  # noqa: E731
    return {"report_column": col, "kappa_report": get(col), "ci_low_report": get(f"{col}_ci_low"),
            "ci_high_report": get(f"{col}_ci_high")}


def _floor_fields(floor, per_segment=None) -> dict:
    """The view's floor fields from a :class:`~rce_gtsam.kappa_floor.KappaFloor` or its report.json dict (None:
    none); ``per_segment``: the rows' floors where they were read elsewhere (compliance_summary.csv)."""
    from ..kappa_floor import KappaFloor
    if floor is None:
        return {"floor_log_rmse": per_segment}
    if isinstance(floor, dict):
        floor = KappaFloor.from_dict(floor)
    return {"floor_log_rmse": floor.log_rmse_per_segment if per_segment is None else per_segment,
            "floor_text": floor.line()}


def _turning_deg(pg, pj, pc) -> np.ndarray:
    """Signed turning angle at pj in degrees (0 = straight), the analysis' convention."""
    a, b = pj - pg, pc - pj
    return np.degrees(np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
                                 a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]))


def predicted_skeleton(graph: BranchGraph, node_ids, xy: np.ndarray, frames: np.ndarray,
                       edges: list[tuple[int, int]], pred: np.ndarray, rest_deg: np.ndarray,
                       rest_length_px: dict, signed: bool, delta_obs: np.ndarray | None = None) -> np.ndarray:
    """(N, F, 2) node positions implied by the model's predicted bending, NaN outside ``frames``.

    xy: (N, F, 2) measured (smoothed) positions, pixels. edges/pred/rest_deg: the response rows, the
    predicted response (E, T) in degrees and each bend's rest angle (the angle its deviation is measured
    from: signed turning angle, or the paper's unsigned interior angle in [0, 180]).
    For the unsigned ``abs`` response the model predicts |delta| only; the sign of the deviation is taken
    from the observed delta (``delta_obs``, carried forward over missing frames), and the turning
    direction from the measured pose.
    """
    row = {int(n): i for i, n in enumerate(node_ids)}
    N, F, _ = xy.shape
    out = np.full((N, F, 2), np.nan)
    T = len(frames)
    if T == 0:
        return out
    P = xy[:, frames]  # (N, T, 2)
    erow = {e: i for i, e in enumerate(edges)}
    turn = {}  # edge -> (T,) predicted signed turning angle, degrees
    for e, i in erow.items():
        j, c = e
        g = graph.parent[j]
        if signed:
            turn[e] = rest_deg[i] + pred[i]
            continue
        meas = _turning_deg(P[row[g]], P[row[j]], P[row[c]])
        side = np.sign(np.nanmedian(meas)) or 1.0
        s = np.ones(T)
        if delta_obs is not None:
            s = pd.Series(np.sign(delta_obs[i])).replace(0, np.nan).ffill().bfill().fillna(1.0).to_numpy()
        interior = rest_deg[i] + s * pred[i]
        turn[e] = side * (180.0 - interior)
    heading = {}
    pos = {graph.root: P[row[graph.root]]}
    for n in graph.nodes[1:]:
        p = graph.parent[n]
        e = (p, n)
        if p == graph.root or e not in turn:
            d = P[row[n]] - P[row[p]]
            h = np.arctan2(d[:, 1], d[:, 0])
        else:
            h = heading[(graph.parent[p], p)] + np.radians(turn[e])
        heading[e] = h
        L = float(rest_length_px.get(e, np.nan))
        pos[n] = pos[p] + L * np.stack([np.cos(h), np.sin(h)], axis=-1)
    for n, p_ in pos.items():
        out[row[n], frames] = p_
    return out


def covariance_ellipses(cov: np.ndarray, centers: np.ndarray, n_sigma: float = 2.0,
                        n_points: int = 17) -> np.ndarray:
    """(..., n_points, 2) closed polylines of the n-sigma ellipses of 2x2 covariances ``cov`` (..., 2, 2)
    around ``centers`` (..., 2), pixels. Non-finite covariances give NaN polylines."""
    c = np.nan_to_num(cov)
    c = 0.5 * (c + np.swapaxes(c, -1, -2))
    w, V = np.linalg.eigh(c)
    A = V * (n_sigma * np.sqrt(np.clip(w, 0, None)))[..., None, :]  # (..., 2, 2) columns scaled
    t = np.linspace(0, 2 * np.pi, n_points)
    circle = np.stack([np.cos(t), np.sin(t)], axis=0)  # (2, P)
    pts = np.einsum("...ij,jp->...pi", A, circle) + centers[..., None, :]
    bad = ~np.isfinite(cov).all(axis=(-1, -2)) | ~np.isfinite(centers).all(axis=-1)
    pts[bad] = np.nan
    return pts


def worst_edges(view: AnalysisView, k: int = 3) -> list[tuple[int, int]]:
    """The ``k`` edges with the largest residual RMS (ties: closer to the tip first)."""
    res = view.residual
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nanmean(res ** 2, axis=1)) if res.size else np.array([])
    order = sorted(range(len(view.edges)), key=lambda i: (-np.nan_to_num(rms[i], nan=-1), -view.root_distance_px[i]))
    return [view.edges[i] for i in order[:k]]
