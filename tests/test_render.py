"""Tests of the video rendering of a simulation (rce_gtsam.render)."""

from __future__ import annotations

import cv2
import numpy as np

from rce_gtsam.render import iter_frames, render_video
from rce_gtsam.simulate import SimulationConfig, simulate


def _sim(n_frames=40, seed=0):
    return simulate(SimulationConfig(n_frames=n_frames, seed=seed))


def test_mp4_decodes_with_opencv_to_right_size_and_count(tmp_path):
    sim = _sim()
    path = render_video(sim, tmp_path / "v.mp4")
    cap = cv2.VideoCapture(str(path))
    n, shape = 0, None
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        n += 1
        shape = frame.shape
    cap.release()
    assert n == 40 and shape == (480, 640, 3)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp file left


def test_h264_yuv420p_for_rerun(tmp_path):
    import av
    path = render_video(_sim(n_frames=12), tmp_path / "v.mp4")
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        assert s.codec_context.name == "h264" and s.codec_context.pix_fmt == "yuv420p"
        assert float(s.average_rate) == 30.0


def test_frames_are_deterministic_and_stem_is_drawn_at_true_positions():
    sim = _sim(n_frames=10)
    a = list(iter_frames(sim, n_frames=3))
    b = list(iter_frames(sim, n_frames=3))
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    bg = next(iter_frames(simulate(SimulationConfig(n_frames=10, seed=0)), n_frames=1, sensor_noise=0))
    # pixels on the stem differ from the background rendering without the stem: compare against a frame
    # where nodes are moved far away (translate true_xy out of the image)
    from dataclasses import replace
    away = replace(sim, true_xy=sim.true_xy + 10_000)
    empty = next(iter_frames(away, n_frames=1, sensor_noise=0))
    diff = np.abs(bg.astype(int) - empty.astype(int)).sum(-1)
    for x, y in sim.true_xy[:, 0]:
        assert diff[int(round(y)), int(round(x))] > 0
    assert (diff > 0).mean() < 0.1  # the stem covers a small part of the image


def test_lucas_kanade_follows_the_rendered_nodes(tmp_path):
    """A plain pyramidal LK tracker follows the proximal half of the nodes to well under a pixel."""
    sim = _sim(n_frames=60, seed=1)
    frames = [cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) for f in iter_frames(sim)]
    half = sim.true_xy.shape[0] // 2
    pts = sim.true_xy[:half, 0].astype(np.float32).reshape(-1, 1, 2)
    errs = []
    for f in range(1, len(frames)):
        pts, _, _ = cv2.calcOpticalFlowPyrLK(frames[f - 1], frames[f], pts, None, winSize=(15, 15), maxLevel=3)
        errs.append(np.linalg.norm(pts.reshape(-1, 2) - sim.true_xy[:half, f], axis=1))
    assert np.median(errs) < 0.5
