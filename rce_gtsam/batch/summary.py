"""The batch summary: one table row per recording x segment, and a JSON document per recording.

``summary.csv`` columns: ``id``, the manifest's metadata columns, ``status`` (ok / failed), ``kind``
(video / tracks), ``preset``, ``verdict`` (the diagnosis' missing effect, ``none`` when the rank-1 model is
not beaten), ``diagnosis_status`` (what a ``none`` means: ``adequate`` — the rest is at the noise floor —,
``misses`` — more than noise is left and no candidate explains it —, ``inconclusive``; ``effect`` with a
verdict; diagnosis.json's ``status``), ``tracker_error_px`` and ``kappa_floor`` (what limits kappa: the tracker's
error across the branch estimated from the residuals, px, and the kappa log-RMSE that error alone allows;
report.json's ``kappa_floor``, empty without one), then every column of the recording's ``compliance_summary.csv`` for
each segment with a bend (parent, child, depth, zone, root_distance_px, rest_length_px, kappa, kappa_ci_low,
kappa_ci_high, uncertainty = U_e, a ``quality`` column when the analysis writes one, ..., fit_rmse_deg; after a
verdict whose model was fitted also ``kappa_<effect>`` and its CI and quality), then ``kappa_to_report``,
``kappa_to_report_ci_low``, ``kappa_to_report_ci_high`` and ``kappa_to_report_quality``: the κ each recording's
``report`` column names (the rank-1 ``kappa`` or ``kappa_<effect>``), so recordings compare in one column; and
``error``.
A failed recording has one row with its error and empty segment columns.

``summary.json``: ``{"batch": {...counts, timing, manifest, options...}, "recordings": [{id, status,
error, metadata, verdict, diagnosis_status, budget, explanation, kappa_floor, heldout_rmse_deg: {baseline, verdict},
elapsed_s, worker, folder, segments: [...]}, ...]}``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .manifest import Manifest
from .process import Outcome

#: Per-recording columns that come before the segment columns.
RECORDING_COLUMNS = ("id", "status", "kind", "preset", "verdict", "diagnosis_status", "tracker_error_px",
                     "kappa_floor")


@dataclass(frozen=True)
class RecordingSummary:
    """One recording's results as read back from its folder. segments: the compliance_summary rows of
    the segments with a bend (empty when failed). diagnosis: diagnosis.json (None when failed)."""

    id: str
    status: str
    kind: str
    preset: str | None
    metadata: dict
    outcome: Outcome
    segments: pd.DataFrame
    diagnosis: dict | None
    folder: Path
    kappa_floor: dict | None = None

    @property
    def verdict(self) -> str | None:
        if self.diagnosis is None:
            return None
        return self.diagnosis.get("verdict") or "none"

    @property
    def diagnosis_status(self) -> str | None:
        """diagnosis.json's ``status``: effect, adequate, misses, inconclusive, untested or uncalibrated (None
        when failed)."""
        return None if self.diagnosis is None else self.diagnosis.get("status")


#: The columns :func:`with_kappa_to_report` adds: the κ to report, its 95 % CI and quality, whichever model it is from.
TO_REPORT = ("kappa_to_report", "kappa_to_report_ci_low", "kappa_to_report_ci_high", "kappa_to_report_quality")


def with_kappa_to_report(segments: pd.DataFrame) -> pd.DataFrame:
    """``segments`` (compliance_summary.csv rows) with :data:`TO_REPORT` copied from the columns its ``report`` column
    names (``kappa``, or ``kappa_<effect>`` after a verdict whose model was fitted), so the recordings of a batch
    compare in one set of columns whatever each one's diagnosis named; unchanged without a ``report`` column."""
    if "report" not in segments or segments.empty:
        return segments
    col = str(segments["report"].iloc[0])
    if col not in segments:
        return segments
    out = segments.copy()
    quality = f"{col}_quality" if col != "kappa" else "quality"
    for name, src in zip(TO_REPORT, (col, f"{col}_ci_low", f"{col}_ci_high", quality)):
        out[name] = out[src] if src in out else np.nan
    return out


def read_recordings(manifest: Manifest, out: Path, outcomes: dict[str, Outcome], options) -> list[RecordingSummary]:
    """Read every recording's outputs back from ``out/<id>/`` (manifest order)."""
    rows = []
    for rec in manifest.recordings:
        folder = out / rec.id
        oc = outcomes[rec.id]
        segments, diagnosis, preset, floor = pd.DataFrame(), None, None, None
        if oc.status != "failed":
            comp = pd.read_csv(folder / "compliance_summary.csv")
            segments = with_kappa_to_report(comp[comp["kappa"].notna() | (comp["n_frames"] > 0)].reset_index(drop=True))
            diagnosis = json.loads((folder / "diagnosis.json").read_text())
            report = json.loads((folder / "report.json").read_text())
            preset, floor = report["preset"]["name"], report.get("kappa_floor")
        else:
            preset = options.preset_for(rec).name
        rows.append(RecordingSummary(id=rec.id, status="failed" if oc.status == "failed" else "ok", kind=rec.kind,
                                     preset=preset, metadata=dict(rec.metadata), outcome=oc, segments=segments,
                                     diagnosis=diagnosis, folder=folder, kappa_floor=floor))
    return rows


def summary_table(manifest: Manifest, recordings: list[RecordingSummary]) -> pd.DataFrame:
    """The ``summary.csv`` table (see the module docstring)."""
    frames, seg_cols = [], []
    for r in recordings:
        for c in r.segments.columns:
            if c not in seg_cols:
                seg_cols.append(c)
    # the kappa each recording reports last (before error), whichever recording first brought the columns
    seg_cols = [c for c in seg_cols if c not in TO_REPORT] + [c for c in TO_REPORT if c in seg_cols]
    for r in recordings:
        floor = r.kappa_floor or {}
        head = {"id": r.id, **r.metadata, "status": r.status, "kind": r.kind, "preset": r.preset,
                "verdict": r.verdict, "diagnosis_status": r.diagnosis_status,
                "tracker_error_px": floor.get("node_error_px"), "kappa_floor": floor.get("log_rmse")}
        if r.segments.empty:
            df = pd.DataFrame([head])
        else:
            df = r.segments.copy()
            for k, v in reversed(list(head.items())):
                df.insert(0, k, v)
        df["error"] = r.outcome.error
        frames.append(df)
    cols = ["id", *manifest.metadata_columns, *RECORDING_COLUMNS[1:], *seg_cols, "error"]
    table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=cols)
    ints = {c for r in recordings for c in r.segments.columns if pd.api.types.is_integer_dtype(r.segments[c])}
    for c in ints:  # a failed recording's empty cells would turn integer columns (parent, child...) into floats
        table[c] = table[c].astype("Int64")
    return table.reindex(columns=cols)


def summary_document(manifest: Manifest, recordings: list[RecordingSummary], batch: dict) -> dict:
    """The ``summary.json`` document (see the module docstring)."""
    from ..jsonutil import jsonable

    docs = []
    for r in recordings:
        d = r.diagnosis or {}
        verdict = d.get("verdict_effect", d.get("verdict"))  # the candidate (a form of the finding named)
        cand = {c.get("effect"): c for c in d.get("candidates", [])}
        docs.append({
            "id": r.id, "status": r.status, "kind": r.kind, "preset": r.preset, "metadata": r.metadata,
            "error": r.outcome.error, "error_kind": r.outcome.error_kind, "computed": r.outcome.status != "skipped",
            "elapsed_s": r.outcome.elapsed_s, "worker": r.outcome.worker, "folder": str(r.folder.resolve()),
            "verdict": r.verdict, "diagnosis_status": r.diagnosis_status, "budget": d.get("budget"),
            "explanation": d.get("explanation"), "kappa_floor": r.kappa_floor,
            "heldout_rmse_deg": None if r.diagnosis is None else {
                "baseline": (d.get("baseline") or {}).get("heldout_rmse"),
                "verdict": cand[verdict].get("heldout_rmse") if verdict in cand else None},
            "segments": r.segments.to_dict(orient="records"),
        })
    return jsonable({"batch": batch, "recordings": docs})
