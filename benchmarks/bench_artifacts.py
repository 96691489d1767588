"""False verdicts and the noise floor under each tracker-artifact family (:mod:`rce_gtsam.sim.artifacts`).

Per case: an effect-free recording ``simulate(SimulationConfig(seed=s, n_frames=F, artifacts=ArtifactConfig(
(family,), scale)))`` (the default tracker noise plus one artifact family at ``scale`` x its measured size;
``none`` = the default noise alone) -> ``analyze(preset="default", n_boot=0)`` -> ``diagnose`` (the default
preset's core model, as ``rce diagnose`` runs it; the same call as ``benchmarks/bench_diagnose.py``).

Printed per family and scale: false verdicts (any verdict on effect-free data is false) and which effects were
named; the noise-floor ratio = estimated angle-noise RMS (:func:`rce_gtsam.diagnosis.noise_floor.noise_floor_of`)
/ true angle-noise RMS (RMS of the smoothed bend angles less the truth on the pipeline's rest reference, as
``benchmarks/bench_noise_floor.py``), median and the count within 25 %; the raw angle noise before smoothing
(:func:`rce_gtsam.sim.simulate.angle_noise_deg`); the share of missing observations; the variance budget's status.

``--cache DIR`` keeps each case's pipeline output (one .npz per family, scale, seed, length: the keys of
``bench_diagnose.cached_case`` -- Y, W, s, k, y, labels -- plus the noise-floor numbers), so the diagnosis can be
re-run after a change to it without the pipeline.

The diagnosis gets the one-node check's geometry (each node's Jacobian at the rest pose, from the simulation's
true positions: :func:`node_sensitivity`) as ``rce diagnose`` does; ``--no-geometry`` leaves it out (the check then
drops the carrying node's bends whole, as it did before it had the geometry).

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_artifacts.py [--seeds 5] [--first-seed 0] [--frames 450]
       [--families none,lag,speed_error,gust_occlusion,slide,coloured_along,drift] [--scales 1,2]
       [--cache /work/cache/artifacts] [--workers 2] [--no-geometry] [--record NAME [--note LINE]]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def case(family: str | None, scale: float, seed: int, frames: int) -> dict:
    """The pipeline's output on one effect-free recording with ``family`` at ``scale`` (None: no artifact)."""
    from rce_gtsam.diagnosis.budget import budget_of
    from rce_gtsam.diagnosis.noise_floor import noise_floor_of
    from rce_gtsam.pipeline import analyze
    from rce_gtsam.sim.artifacts import ArtifactConfig
    from rce_gtsam.sim.simulate import SimulationConfig, angle_noise_deg, simulate

    art = ArtifactConfig(families=(family,), scale=scale) if family else ArtifactConfig()
    sim = simulate(SimulationConfig(seed=seed, n_frames=frames, artifacts=art))
    t = time.perf_counter()
    res = analyze(sim.tracks, sim.graph, preset="default", n_boot=0)
    tp = time.perf_counter() - t
    r = res.response
    row = {b.edge: i for i, b in enumerate(sim.graph.bends)}
    y = sim.response_true[[row[tuple(e)] for e in r.edges]][:, r.frames]
    yref = y + np.nanmean(r.Y - y, axis=1, keepdims=True)
    nf = noise_floor_of(res)
    try:
        status = budget_of(res).status
    except Exception as err:  # noqa: BLE001 - report, do not stop the bench
        status = f"error: {type(err).__name__}"
    W = r.weights if res.preset.compliance.weighted else None
    return {"Y": r.Y, "W": W if W is not None else np.array([]), "s": r.root_distance,
            "k": np.array([sim.kappa_true[e] for e in r.edges]), "y": y, "labels": np.array(r.edge_labels),
            "nf_rms": nf.rms_deg, "true_rms": float(np.sqrt(np.nanmean((r.Y - yref) ** 2))),
            "raw_angle_noise": angle_noise_deg(sim), "missing": float(1 - sim.tracks.observed.mean()),
            "budget": status, "pipeline_s": tp}


#: the noise floor's version in the cache's file names: a case cached before the floor changed is run again
#: (the node-wise estimate joined the floor in v2; its kappa-step correction in v3)
FLOOR_TAG = "_nf3"


def preset_tag(family: str | None) -> str:
    """A short fingerprint of the family's measured parameters, so that a re-measured preset is not read from
    the cache of an older one (empty for no artifact)."""
    if not family:
        return ""
    import hashlib
    import json

    from rce_gtsam.sim.artifacts import load_preset
    text = json.dumps(load_preset()[family], sort_keys=True)
    return "_p" + hashlib.sha1(text.encode()).hexdigest()[:8]


def cached(cache: str | None, family: str | None, scale: float, seed: int, frames: int) -> dict:
    """:func:`case`, kept in (and read back from) ``cache`` when given."""
    if cache is None:
        return case(family, scale, seed, frames)
    path = Path(cache) / f"artifact_{family or 'none'}_{scale:g}_{seed}_{frames}{preset_tag(family)}{FLOOR_TAG}.npz"
    if path.exists():
        d = dict(np.load(path))
        d = {k: (v.item() if v.ndim == 0 else v) for k, v in d.items()}
        d["pipeline_s"] = 0.0
        return d
    d = case(family, scale, seed, frames)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part.npz")
    np.savez(tmp, **d)
    tmp.replace(path)
    return d


def node_sensitivity(family: str | None, scale: float, seed: int, frames: int, labels) -> dict | None:
    """The one-node check's geometry for a case's rows (``"joint->child"`` labels), as ``rce diagnose`` hands it over
    (:func:`rce_gtsam.diagnosis.io.node_sensitivity_of`): each node's Jacobian at the rest pose, here the median of
    the simulation's true positions (the pipeline takes its smoothed ones), keyed by the label's node text."""
    from rce_gtsam.diagnosis.one_node import bend_jacobian
    from rce_gtsam.sim.artifacts import ArtifactConfig
    from rce_gtsam.sim.simulate import SimulationConfig, simulate

    art = ArtifactConfig(families=(family,), scale=scale) if family else ArtifactConfig()
    sim = simulate(SimulationConfig(seed=seed, n_frames=frames, artifacts=art))
    rest = {int(n): np.median(sim.true_xy[i], axis=0) for i, n in enumerate(sim.tracks.node_ids)}
    parent = {int(c): int(p) for p, c in sim.graph.edges}
    triples = []
    for lab in labels:
        j, c = (int(x) for x in str(lab).split("->"))
        if j not in parent:
            return None
        triples.append((parent[j], j, c))
    J = bend_jacobian(triples, rest)
    return None if J is None else {str(n): a for n, a in J.items()}


def verdict_of(c: dict, family, scale, seed, frames, geometry=True):
    """The diagnosis' verdict on one case's pipeline output ``c`` (:func:`cached`; the default preset's core model, as
    ``rce diagnose``), with the one-node check's geometry unless ``geometry`` is False."""
    from rce_gtsam.diagnosis.diagnose import diagnose
    from rce_gtsam.presets import get_preset

    W = c["W"] if np.size(c["W"]) else None
    labels = list(c["labels"])
    sens = node_sensitivity(family, scale, seed, frames, labels) if geometry else None
    return diagnose(c["Y"], weights=W, root_distance=c["s"], seed=0, edge_labels=labels,
                    config=get_preset("default").compliance, node_sensitivity=sens).verdict


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--families", default="none,lag,speed_error,gust_occlusion,slide,coloured_along,drift")
    ap.add_argument("--scales", default="1,2", help="strength multipliers of the measured sizes")
    ap.add_argument("--cache", default=None, help="folder that keeps each case's pipeline output")
    ap.add_argument("--floor-only", action="store_true",
                    help="recompute only the noise floor (no diagnosis); with --record, replace the floor columns of "
                         "the record's rows of the same family and size and keep its verdict columns")
    ap.add_argument("--record", default=None, metavar="NAME",
                    help="save the table as the docs' validation record docs/validation/NAME.json")
    ap.add_argument("--note", action="append", default=[], help="a line under the record's table (repeatable)")
    ap.add_argument("--workers", type=int, default=1, help="processes for the diagnoses (the cases must be cached)")
    ap.add_argument("--no-geometry", action="store_true",
                    help="diagnose without the one-node check's geometry (its rows left out, as before it had one)")
    a = ap.parse_args()
    from rce_gtsam.sim.artifacts import FAMILIES

    fams = [f.strip() for f in a.families.split(",") if f.strip()]
    bad = [f for f in fams if f != "none" and f not in FAMILIES]
    if bad:
        ap.error(f"--families: unknown {bad}; choose from none, {', '.join(FAMILIES)}")
    try:
        scales = [float(x) for x in a.scales.split(",")]
    except ValueError:
        ap.error(f"--scales: not a list of numbers: {a.scales!r}")
    print(f"effect-free recordings, {a.seeds} seeds from {a.first_seed}, {a.frames} frames; one artifact family at "
          f"{a.scales} x its measured size on top of the default tracker noise", flush=True)
    rows = []
    t0 = time.perf_counter()
    for fam in fams:
        for sc in ([1.0] if fam == "none" else scales):
            verdicts, ratios, raw, miss, budgets, tds = [], [], [], [], [], []
            seeds = list(range(a.first_seed, a.first_seed + a.seeds))
            family = None if fam == "none" else fam
            cases = [cached(a.cache, family, sc, sd, a.frames) for sd in seeds]
            t = time.perf_counter()
            if a.floor_only:
                found = [None] * len(seeds)
            else:
                jobs = [({k: c[k] for k in ("Y", "W", "s", "labels")}, family, sc, sd, a.frames, not a.no_geometry)
                        for c, sd in zip(cases, seeds)]
                if a.workers > 1:
                    with ProcessPoolExecutor(a.workers) as pool:
                        found = list(pool.map(verdict_of, *zip(*jobs)))
                else:
                    found = [verdict_of(*job) for job in jobs]
            per_case = (time.perf_counter() - t) / len(seeds)
            for sd, c, verdict in zip(seeds, cases, found):
                tds.append(per_case)
                verdicts.append(verdict)
                ratios.append(c["nf_rms"] / c["true_rms"])
                raw.append(c["raw_angle_noise"])
                miss.append(c["missing"])
                budgets.append(str(c["budget"]))
                print(f"  {fam} x{sc:g} seed {sd}: verdict {verdict}; noise floor {c['nf_rms']:.3f} / true "
                      f"{c['true_rms']:.3f} deg = {ratios[-1]:.2f}; raw angle noise {raw[-1]:.3f} deg; missing "
                      f"{100 * miss[-1]:.1f} %; budget {budgets[-1]} (pipeline {c['pipeline_s']:.1f} s, diagnose "
                      f"{tds[-1]:.1f} s)", flush=True)
            named = Counter(v for v in verdicts if v is not None)
            r = np.array(ratios)
            rows.append((fam, sc, sum(v is not None for v in verdicts), len(verdicts), dict(named),
                         float(np.median(r)), float(r.min()), float(r.max()), int(np.sum(np.abs(r - 1) <= 0.25)),
                         float(np.median(raw)), float(np.median(miss)), dict(Counter(budgets))))
    print(f"\n{'family':<15} {'x':>4} {'false':>7} {'named':<28} {'floor/true median [range]':>27} {'<=25%':>6} "
          f"{'raw deg':>8} {'missing':>8}  budget")
    for fam, sc, nf, n, named, med, lo, hi, w25, rw, ms, bud in rows:
        nm = ", ".join(f"{k} {v}" for k, v in named.items()) or "-"
        print(f"{fam:<15} {sc:>4g} {nf:>3}/{n:<3} {nm:<28} {med:>10.2f} [{lo:.2f}-{hi:.2f}]{'':>6} {w25:>3}/{n:<2} "
              f"{rw:>8.3f} {100 * ms:>7.1f}%  {bud}")
    print(f"({time.perf_counter() - t0:.0f} s)")
    if a.record and a.floor_only:
        update_floor_columns(a.record, rows, a)
    elif a.record:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from record import save_record
        save_record(a.record, title=(f"Tracker-artifact families: false verdicts and the noise floor ({a.seeds} seeds "
                                     f"each, at the measured size and twice it)"),
                    command=(f"python benchmarks/bench_artifacts.py --seeds {a.seeds} --first-seed {a.first_seed} "
                             f"--frames {a.frames} --families {a.families} --scales {a.scales} --cache DIR"),
                    description=(f"Effect-free simulated recordings ({a.frames} frames, 20 nodes) with the default "
                                 "tracker noise plus one artifact family at its measured size (x1) or twice it (x2), "
                                 "through analyze and diagnose (default preset). Any verdict is false. Noise floor / "
                                 "true: the diagnosis' angle-noise floor over the true angle-noise RMS."),
                    columns=["family", "x measured size", "false verdicts", "names", "noise floor / true (median)",
                             "range", "within 25 %"],
                    rows=[[fam, int(sc) if float(sc).is_integer() else sc, f"{nf} of {n}",
                           ", ".join(f"{k} {v}" for k, v in named.items()) or "-",
                           round(med, 2), f"{lo:.2f}-{hi:.2f}", f"{w25} of {n}"]
                          for fam, sc, nf, n, named, med, lo, hi, w25, rw, ms, bud in rows], notes=a.note)
    return 0


def update_floor_columns(name: str, rows: list, a) -> None:
    """Replace the noise-floor columns of record ``name``'s rows of the families and sizes in ``rows`` (the
    verdict columns stay: the diagnosis reads no noise floor here), and say so in its notes; written back through
    ``record.save_record`` (its schema check, directory and atomic write), keeping the record's date."""
    import datetime

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from record import load_record, record_dir, save_record
    path = record_dir() / f"{name}.json"
    rec = load_record(name)
    cols = rec["columns"]
    i_med, i_rng, i_25 = (cols.index(c) for c in ("noise floor / true (median)", "range", "within 25 %"))
    done = []
    for fam, sc, nf, n, named, med, lo, hi, w25, rw, ms, bud in rows:
        for r in rec["rows"]:
            if r[0] == fam and float(r[1]) == float(sc):
                r[i_med], r[i_rng], r[i_25] = round(med, 2), f"{lo:.2f}-{hi:.2f}", f"{w25} of {n}"
                done.append(f"{fam} x{sc:g}")
    if not done:
        print(f"{path}: no row of these families and sizes, nothing updated")
        return
    note = (f"Noise-floor columns of {', '.join(done)} recomputed with the node-wise floor "
            f"(python benchmarks/bench_artifacts.py --floor-only --seeds {a.seeds} --families {a.families} "
            f"--scales {a.scales}; {datetime.date.today()}); the verdict columns are the diagnosis', which reads no "
            f"noise floor.")
    notes = [n for n in rec.get("notes", []) if not n.startswith("Noise-floor columns of " + done[0].split()[0])]
    written = save_record(name, title=rec["title"], command=rec["command"], columns=cols, rows=rec["rows"],
                          description=rec["description"], notes=notes + [note], date=rec["date"],
                          directory=path.parent)
    print(f"updated the floor columns of {written}: {', '.join(done)}")


if __name__ == "__main__":
    sys.exit(main())
