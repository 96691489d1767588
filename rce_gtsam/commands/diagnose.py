"""``rce diagnose TRACKS GRAPH --json PATH``: which physical effect does the rank-1 model miss?"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

from ..presets import PRESETS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="compare the rank-1 model with the measurements; find the missing effect",
                       description="Run the analysis up to the bend-response matrix, then fit the rank-1 model and "
                                   "each candidate effect, score them on held-out frames (blocked CV) and print a "
                                   "verdict with its physical explanation.")
    p.add_argument("tracks", type=Path, help="tracks CSV: point_id,frame,x,y[,visible,sigma_px] (pixels)")
    p.add_argument("graph", type=Path, help='branch graph JSON: {"root": id, "edges": [[parent, child], ...]}')
    p.add_argument("--json", type=Path, required=True, dest="json_path", help="write the diagnosis JSON here")
    p.add_argument("--preset", choices=sorted(PRESETS), default="default", help="method preset")
    p.add_argument("--effects", default=None,
                   help="comma-separated candidates (default: delay,dynamics,second_mode,offset,nonlinear)")
    p.add_argument("--seed", type=int, default=0, help="seed of the stratified edge split (default 0)")
    p.add_argument("--folds", type=int, default=8, help="cross-validation blocks (default 8)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..diagnose import diagnose
    from ..effects import EFFECT_NAMES
    from ..errors import InputError
    from ..pipeline import analyze

    names = None
    if args.effects:
        names = [n.strip() for n in args.effects.split(",") if n.strip()]
        bad = [n for n in names if n not in EFFECT_NAMES]
        if bad:
            raise InputError("--effects", f"unknown effect(s) {bad}; known: {', '.join(EFFECT_NAMES)}")
    result = analyze(args.tracks, args.graph, preset=args.preset, n_boot=0)
    resp, cfg = result.response, result.preset.compliance
    weights = resp.weights if cfg.weighted else None
    diag = diagnose(resp.Y, weights=weights, root_distance=resp.root_distance, effects=names,
                    n_folds=args.folds, seed=args.seed, block_length=cfg.block_length,
                    prior_strength=cfg.prior_strength, response=cfg.response,
                    edge_labels=[f"{j}->{c}" for j, c in resp.edges], frames=resp.frames)
    data = diag.as_dict()
    data["inputs"] = {"tracks": str(args.tracks), "graph": str(args.graph), "preset": args.preset}
    write_json_atomic(data, args.json_path)
    print(diag.report())
    print(f"\nwrote {args.json_path}")
    return 0


def write_json_atomic(data: dict, path: Path) -> None:
    """Write JSON to a temporary file in the same folder, then rename (never a half-written file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=1)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
