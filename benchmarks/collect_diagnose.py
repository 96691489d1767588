"""Merge the per-case lines of several ``bench_diagnose.py`` runs (e.g. seed blocks run in parallel) into one
detection-vs-strength table, project against oracle.

Usage: python benchmarks/collect_diagnose.py RUN.txt [RUN.txt ...]
A case seen in several files counts once (the last file wins: re-runs replace earlier ones).
"""

from __future__ import annotations

import re
import sys
from collections import defaultdict

LINE = re.compile(r"^\s+(?P<eff>\w+) x(?P<mult>[0-9.]+) seed (?P<seed>\d+): verdict (?P<v>\w+) "
                  r"\((?:same-kind parsimony: (?P<v2>\w+); )?(?:max-T: (?P<v3>\w+)(?P<o3>, oracle max-T\*)?; )?"
                  r"full-data test: (?P<fv>\w+)\), oracle t=(?P<ot>[-0-9.naninf]+)"
                  r"(?P<ostar>\*?)")
LAG = {"delay", "dynamics"}


def main(paths: list[str]) -> int:
    cases = {}
    for p in paths:
        for line in open(p):
            m = LINE.match(line)
            if m:
                d = m.groupdict()
                d["v2"] = d["v2"] or d["v"]  # runs before the same-kind column: only a name could differ, and
                # only where something is supported (not on effect-free data)
                cases[(m["eff"], float(m["mult"]), int(m["seed"]))] = d
    cells = defaultdict(list)
    for (eff, mult, seed), m in cases.items():
        cells[(eff, mult)].append(m)
    print(f"{'effect':<12} {'x':>4} {'n':>3} {'right':>6} {'oracle':>6} {'right2':>6} {'DM':>5} "
          f"{'lag<->lag':>9} {'lag<->lag2':>10} {'lag conf. where oracle fires':>28} {'n3':>4} {'right3':>6} "
          f"{'oracle3':>7} {'lag<->lag3':>10}")
    per_eff = defaultdict(list)
    per_eff3 = defaultdict(list)
    for (eff, mult) in sorted(cells):
        ms = cells[(eff, mult)]
        hidden = None if eff == "none" else eff
        n = len(ms)
        def right(v):
            return (v == "None") if hidden is None else (v == hidden)
        r = sum(right(m["v"]) for m in ms)
        r2 = sum(right(m["v2"]) for m in ms)
        dm = sum(right(m["fv"]) for m in ms)
        o = sum(m["ostar"] == "*" for m in ms)
        conf = sum(hidden in LAG and m["v"] in LAG - {hidden} for m in ms)
        conf2 = sum(hidden in LAG and m["v2"] in LAG - {hidden} for m in ms)
        fired = [m for m in ms if m["ostar"] == "*"]
        conf_o = sum(hidden in LAG and m["v"] in LAG - {hidden} for m in fired)
        m3 = [m for m in ms if m["v3"] is not None]
        r3 = sum(right(m["v3"]) for m in m3)
        o3 = sum(bool(m["o3"]) for m in m3)
        conf3 = sum(hidden in LAG and m["v3"] in LAG - {hidden} for m in m3)
        print(f"{eff:<12} {mult:>4g} {n:>3} {r:>6} {o:>6} {r2:>6} {dm:>5} {conf:>9} {conf2:>10} "
              f"{f'{conf_o}/{len(fired)}':>28} {len(m3):>4} {r3:>6} {o3:>7} {conf3:>10}")
        per_eff[eff].append((mult, n, r, o, r2))
        per_eff3[eff].append((mult, len(m3), r3, o3))
    print()
    for eff, rows in per_eff.items():
        if eff == "none":
            continue
        p90 = next((m for m, n, r, o, r2 in rows if r >= 0.9 * n), None)
        o90 = next((m for m, n, r, o, r2 in rows if o >= 0.9 * n), None)
        p902 = next((m for m, n, r, o, r2 in rows if r2 >= 0.9 * n), None)
        ratio = (f"{p90 / o90:.2g}x the oracle's" if p90 is not None and o90 is not None else "n/a")
        r3 = [(m, n, r, o) for m, n, r, o in per_eff3[eff] if n > 0]
        p3 = next((m for m, n, r, o in r3 if r >= 0.9 * n), None)
        o3 = next((m for m, n, r, o in r3 if o >= 0.9 * n), None)
        print(f"{eff:<12} right >= 90 % from x{p90 if p90 is not None else '>3'} (same-kind parsimony "
              f"x{p902 if p902 is not None else '>3'}); oracle from x{o90 if o90 is not None else '>3'}; {ratio}; "
              f"max-T rule: right from x{p3 if p3 is not None else '>3'}, its oracle from x{o3 if o3 is not None else '>3'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
