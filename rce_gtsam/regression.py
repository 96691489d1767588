"""Compare an analysis with the published reference outputs (``reference/compliance_summary.csv``).

Used by ``regression/run_regression.py`` and the test suite: the ``paper`` preset must reproduce the
published plant-2 kappa to 0.001 and CI bounds to 0.02.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .errors import InputError

KAPPA_TOLERANCE = 1e-3
CI_TOLERANCE = 2e-2
REFERENCE_COLUMNS = {"relative_compliance_kappa": "ref_kappa", "relative_compliance_ci_low": "ref_ci_low",
                     "relative_compliance_ci_high": "ref_ci_high"}


@dataclass(frozen=True, eq=False)
class RegressionReport:
    """table: per edge ours vs published; max_*: largest absolute differences over edges."""

    table: pd.DataFrame
    max_kappa_diff: float
    max_ci_low_diff: float
    max_ci_high_diff: float

    @property
    def passed(self) -> bool:
        return (self.max_kappa_diff <= KAPPA_TOLERANCE and self.max_ci_low_diff <= CI_TOLERANCE
                and self.max_ci_high_diff <= CI_TOLERANCE)

    def format(self) -> str:
        lines = [self.table.to_string(index=False, float_format=lambda v: f"{v:.5f}"), "",
                 f"max |kappa - published|   = {self.max_kappa_diff:.2e} (tolerance {KAPPA_TOLERANCE})",
                 f"max |CI low - published|  = {self.max_ci_low_diff:.2e} (tolerance {CI_TOLERANCE})",
                 f"max |CI high - published| = {self.max_ci_high_diff:.2e} (tolerance {CI_TOLERANCE})",
                 "PASS" if self.passed else "FAIL"]
        return "\n".join(lines)


def compare_with_reference(summary: pd.DataFrame, reference_csv: str | Path) -> RegressionReport:
    """Join our compliance summary with a published ``compliance_summary.csv`` on (parent, child)."""
    reference_csv = Path(reference_csv)
    if not reference_csv.is_file():
        raise InputError(reference_csv, "reference compliance_summary.csv not found")
    ref = pd.read_csv(reference_csv)
    missing = [c for c in ["parent", "child", *REFERENCE_COLUMNS] if c not in ref.columns]
    if missing:
        raise InputError(reference_csv, f"missing column(s) {missing}")
    ref = ref[["parent", "child", *REFERENCE_COLUMNS]].rename(columns=REFERENCE_COLUMNS)
    ours = summary[["parent", "child", "kappa", "kappa_ci_low", "kappa_ci_high"]]
    t = ours.merge(ref, on=["parent", "child"], how="outer", indicator=True)
    unmatched = t[t["_merge"] != "both"]
    if len(unmatched):
        raise InputError(reference_csv, "edges differ between the analysis and the reference: "
                                        f"{unmatched[['parent', 'child']].values.tolist()}")
    t = t.drop(columns="_merge").dropna(subset=["ref_kappa"])
    t["kappa_diff"] = t["kappa"] - t["ref_kappa"]
    t["ci_low_diff"] = t["kappa_ci_low"] - t["ref_ci_low"]
    t["ci_high_diff"] = t["kappa_ci_high"] - t["ref_ci_high"]
    return RegressionReport(table=t, max_kappa_diff=float(t["kappa_diff"].abs().max()),
                            max_ci_low_diff=float(t["ci_low_diff"].abs().max()),
                            max_ci_high_diff=float(t["ci_high_diff"].abs().max()))
