"""Shared fixtures: the real plant data beside the repo and a small synthetic chain."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import settings

# property tests draw their examples from a seed fixed per test, so that a run of the suite is repeatable (a
# failure found once names its example in the report; tests/test_quality.py keeps the ones found so far)
settings.register_profile("repeatable", derandomize=True, print_blob=True)
settings.load_profile("repeatable")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository (CI clones main with shared/ next to it)."""
    if not (SHARED_DATA / "plant_2" / "tapir_tracks.csv").is_file():
        pytest.skip(f"real plant data not found at {SHARED_DATA}")
    return SHARED_DATA


def chain_positions(n_nodes: int, n_frames: int, kappa: np.ndarray, z_deg: np.ndarray,
                    seg_px: float = 20.0, origin=(320.0, 440.0)) -> np.ndarray:
    """(N, F, 2) planar chain growing upward; joint k turns by rest + kappa[k-1] * z (degrees)."""
    rest_turn = np.linspace(-3, 3, n_nodes)
    xy = np.zeros((n_nodes, n_frames, 2))
    xy[0] = origin
    heading = np.full(n_frames, -90.0)  # degrees, image y points down: -90 = up
    for i in range(1, n_nodes):
        if i >= 2:
            heading = heading + rest_turn[i - 1] + kappa[i - 2] * z_deg
        xy[i, :, 0] = xy[i - 1, :, 0] + seg_px * np.cos(np.radians(heading))
        xy[i, :, 1] = xy[i - 1, :, 1] + seg_px * np.sin(np.radians(heading))
    return xy


def make_chain(tmp_path: Path, n_nodes: int = 6, n_frames: int = 240, noise_px: float = 0.15, seed: int = 0):
    """Write a small synthetic chain (tracks.csv, graph.json) and return (tracks_csv, graph_json, kappa, z).

    Compliance spans a factor of four so its ordering is well determined at this noise level."""
    rng = np.random.default_rng(seed)
    kappa = np.exp(np.linspace(-0.7, 0.7, n_nodes - 2))[rng.permutation(n_nodes - 2)]
    kappa /= np.exp(np.log(kappa).mean())
    t = np.arange(n_frames)
    z = 2.0 * np.sin(2 * np.pi * t / 60.0) + 1.0 * np.sin(2 * np.pi * t / 23.0 + 1.0)
    xy = chain_positions(n_nodes, n_frames, kappa, z)
    xy = xy + rng.normal(0, noise_px, xy.shape)
    n, f = np.meshgrid(np.arange(n_nodes), t, indexing="ij")
    df = pd.DataFrame({"point_id": n.ravel(), "frame": f.ravel(), "x": xy[..., 0].ravel(), "y": xy[..., 1].ravel()})
    tracks_csv = tmp_path / "tracks.csv"
    graph_json = tmp_path / "graph.json"
    df.to_csv(tracks_csv, index=False)
    graph_json.write_text(json.dumps({"root": 0, "edges": [[i, i + 1] for i in range(n_nodes - 1)]}))
    return tracks_csv, graph_json, kappa, z


@pytest.fixture
def chain(tmp_path):
    return make_chain(tmp_path)
