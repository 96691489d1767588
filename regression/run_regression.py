"""Re-run the ``paper`` preset on a plant folder with published results and compare.

Usage: python regression/run_regression.py ../shared/data/plant_2 [--preset paper]

The folder must hold tapir_tracks.csv, branch_graph.json and reference/compliance_summary.csv.
Exit code 0 when kappa is within 0.001 and the CI bounds within 0.02 of the published values.
Only plant 2's published results follow from its released tracks (see shared/data/README.md).
"""

import argparse
import sys
from pathlib import Path

import rce_gtsam
from rce_gtsam.regression import compare_with_reference


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("plant_dir", type=Path)
    ap.add_argument("--preset", default="paper")
    args = ap.parse_args()
    d = args.plant_dir
    result = rce_gtsam.analyze(d / "tapir_tracks.csv", d / "branch_graph.json", preset=args.preset)
    report = compare_with_reference(result.summary(), d / "reference" / "compliance_summary.csv")
    print(report.format())
    sm = result.smoothing.as_dict()
    print(f"\nsmoothing: bending RMS {sm['mean_bend_rms_raw_deg']:.3f} -> {sm['mean_bend_rms_smoothed_deg']:.3f} deg "
          f"({sm['bend_rms_reduction_pct']:.2f}% lower over {sm['n_bends']} bends); edge-length CV "
          f"{sm['mean_edge_length_cv_raw']:.4f} -> {sm['mean_edge_length_cv_smoothed']:.4f} "
          f"({sm['edge_length_cv_reduction_pct']:.2f}% lower over {sm['n_edges']} edges)")
    print(f"analysis time {result.timings_s['total']:.2f} s")
    return 0 if report.passed else 1


if __name__ == "__main__":
    sys.exit(main())
