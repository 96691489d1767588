"""Property-based: malformed and degenerate inputs end in exit 0, 2 or 3 (never a traceback), and data with no
signal never yield a kappa of quality ``ok``."""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from rce_gtsam.cli import main

GOOD_WEIGHTS = st.sampled_from(["0", "0.5", "20", "100"])
BAD_WEIGHTS = st.sampled_from(["-1", "nan", "inf", "1e300"])


@st.composite
def cases(draw):
    """Half the cases are well-formed static branches (no signal) with valid options; the other half break
    one thing (frames, frame labels, graph, an option), with the rest as in the good half."""
    case = dict(n_nodes=draw(st.integers(3, 5)), n_frames=draw(st.sampled_from([60, 120])), first=0,
                noise=draw(st.sampled_from([0.0, 0.2, 1.0])), drop=draw(st.sampled_from([0.0, 0.1, 0.4])),
                graph="chain", seed=draw(st.integers(0, 2**16)),
                options=["--bootstrap", str(draw(st.integers(0, 15))), "--seed", str(draw(st.integers(0, 5)))])
    if draw(st.booleans()):
        case["options"] += ["--set", f"smoother.acceleration_weight={draw(GOOD_WEIGHTS)}"]
    if draw(st.booleans()):
        case["options"] += ["--set", f"bending.mad_threshold={draw(st.sampled_from(['0', '1', '3.5']))}"]
    broken = draw(st.sampled_from([None] * 8 + ["n_frames", "first", "graph", "n_nodes", "drop", "bootstrap",
                                                "seed", "weight", "mad"]))
    if broken == "n_frames":
        case["n_frames"] = draw(st.sampled_from([0, 1, 10, 49]))
    elif broken == "first":
        case["first"] = draw(st.integers(1, 10**6))
    elif broken == "graph":
        case["graph"] = draw(st.sampled_from(["cycle", "missing_node", "empty"]))
    elif broken == "n_nodes":
        case["n_nodes"] = 2
    elif broken == "drop":
        case["drop"] = 0.97
    elif broken == "bootstrap":
        case["options"] += ["--bootstrap", str(draw(st.integers(-10**6, -1)))]
    elif broken == "seed":
        case["options"] += ["--seed", str(draw(st.integers(-10**6, -1)))]
    elif broken == "weight":
        case["options"] += ["--set", f"smoother.acceleration_weight={draw(BAD_WEIGHTS)}"]
    elif broken == "mad":
        case["options"] += ["--set", "bending.mad_threshold=-1"]
    return case


def _write(case, folder: Path) -> tuple[Path, Path]:
    rng = np.random.default_rng(case["seed"])
    n, f = case["n_nodes"], case["n_frames"]
    base = np.stack([100 + 25 * np.arange(n), 300 - 4 * np.arange(n) ** 1.5], axis=1)  # a static, bent branch
    rows = []
    for node in range(n):
        for fr in range(f):
            if node and rng.random() < case["drop"]:
                continue
            x, y = base[node] + case["noise"] * rng.standard_normal(2)
            rows.append((node, fr + case["first"], x, y))
    tracks = folder / "tracks.csv"
    pd.DataFrame(rows, columns=["point_id", "frame", "x", "y"]).to_csv(tracks, index=False)
    edges = [[i, i + 1] for i in range(n - 1)]
    if case["graph"] == "cycle":
        edges.append([n - 1, 0])
    elif case["graph"] == "missing_node":
        edges.append([n - 1, n + 3])
    elif case["graph"] == "empty":
        edges = []
    graph = folder / "graph.json"
    graph.write_text(json.dumps({"root": 0, "edges": edges}))
    return tracks, graph


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=cases())
def test_malformed_or_static_input_never_crashes_or_claims_a_trustworthy_kappa(case):
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        tracks, graph = _write(case, tmp)
        out = tmp / "out"
        buf = io.StringIO()
        with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("error")  # a leaked numpy warning is a failure too
            code = main(["analyze", str(tracks), str(graph), "--out", str(out), "--no-figures", "--quiet",
                         *case["options"]])
        err = buf.getvalue()
        event(f"exit {code}")
        assert code in (0, 2, 3), err
        assert "Traceback" not in err and "Warning" not in err, err
        if code == 2:
            assert len(err.strip().splitlines()) == 1, err
            assert not out.exists()
        else:  # every branch here is static: no kappa may be ok
            df = pd.read_csv(out / "compliance_summary.csv").dropna(subset=["kappa"])
            assert not (df["quality"] == "ok").any(), df[["parent", "child", "quality"]]
            assert code == 3 and len(err.strip().splitlines()) == 1, err
            assert all(math.isfinite(k) for k in df["kappa"])
