"""What the quality rules say on real and shipped tracks: ok / uninformative / calm_support / poor_fit counts.

Usage: python benchmarks/bench_quality_rules.py [--shared /work/shared/data] [EXTRA_TRACKS.csv:GRAPH.json ...]

Analyses (default preset, its 250 resamples, seed 0) ``data/sample`` and, where the shared data are there, both
plants' TAPIR tracks; any further ``tracks.csv:graph.json`` pairs too (e.g. our tracker's tracks of plant 2's
footage: ``rce track .../annotated_nodes.mp4 .../annotation_points.json --graph ... --out ours.csv``). Prints,
per data set, how many segments are ok, informative, and carry each reason, and the range of z_var_seen (the
share of the excitation's variance in frames where a segment's nodes were all tracked).
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import numpy as np

from rce_gtsam.pipeline import analyze
from rce_gtsam.quality import REASONS, assess_quality

ROOT = Path(__file__).resolve().parents[1]


def report(name: str, tracks: Path, graph: Path) -> None:
    q = assess_quality(analyze(tracks, graph))
    n = len(q)
    reasons = Counter(r for v in q.values() for r in v.reasons)
    seen = np.array([v.z_var_seen for v in q.values()])
    print(f"{name}: {sum(v.ok for v in q.values())} of {n} ok, "
          f"{sum(v.informative is True for v in q.values())} of {n} informative; "
          + ", ".join(f"{r} {reasons[r]}" for r in REASONS if reasons[r])
          + f"; z_var_seen {np.nanmin(seen):.0%}-{np.nanmax(seen):.0%} (median {np.nanmedian(seen):.0%})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("extra", nargs="*", help="tracks.csv:graph.json pairs")
    a = ap.parse_args()
    report("data/sample", ROOT / "data" / "sample" / "tracks.csv", ROOT / "data" / "sample" / "graph.json")
    for plant in ("plant_1", "plant_2"):
        d = a.shared / plant
        if (d / "tapir_tracks.csv").is_file():
            report(f"{plant} (TAPIR)", d / "tapir_tracks.csv", d / "branch_graph.json")
    for pair in a.extra:
        t, g = pair.split(":")
        report(t, Path(t), Path(g))


if __name__ == "__main__":
    main()
