"""Tests of the video rendering of a simulation (rce_gtsam.sim.render)."""

from __future__ import annotations

import cv2
import numpy as np

from rce_gtsam.sim.render import iter_frames, render_video
from rce_gtsam.sim.simulate import SimulationConfig, simulate


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


def test_default_render_config_is_the_clean_render():
    """No nuisance by default: the frames are the plain composite of background and sprites (+ sensor noise),
    the same with an explicit RenderConfig() and with the ``clean`` preset."""
    from rce_gtsam.sim.nuisance import REALISM, RenderConfig
    from rce_gtsam.sim.render import _blit, build_scene

    sim = _sim(n_frames=10)
    a = list(iter_frames(sim, n_frames=4))
    for cfg in (RenderConfig(), REALISM["clean"]):
        assert all(np.array_equal(x, y) for x, y in zip(a, iter_frames(sim, n_frames=4, config=cfg)))
    background, sprites = build_scene(sim)
    row = {int(n): i for i, n in enumerate(sim.tracks.node_ids)}
    for f, img in enumerate(iter_frames(sim, n_frames=3, sensor_noise=0)):
        canvas = background.copy()
        for sp in sprites:
            _blit(canvas, sp, sim.true_xy[row[sp.edge[0]], f], sim.true_xy[row[sp.edge[1]], f], f / sim.config.fps)
        assert np.array_equal(img, np.clip(canvas + 0.5, 0, 255).astype(np.uint8))


def test_nuisances_change_the_frames_as_intended():
    from rce_gtsam.sim.nuisance import RenderConfig, camera_shift, illumination, image_xy

    sim = _sim(n_frames=60, seed=1)
    clean = [f.astype(float) for f in iter_frames(sim, sensor_noise=0)]
    # illumination: the mean brightness follows the global gain (no offset, no clipping in this scene)
    cfg = RenderConfig(gain_sd=0.25, light_time_s=0.3)
    gain, offset = illumination(sim, cfg)
    lit = [f.astype(float) for f in iter_frames(sim, sensor_noise=0, config=cfg)]
    ratio = np.array([b.mean() / a.mean() for a, b in zip(clean, lit)])
    assert np.ptp(gain) > 0.2 and not offset.any()
    np.testing.assert_allclose(ratio, gain, rtol=0.01)
    # shake: the whole image moves by the camera shift (phase correlation of background-dominated frames)
    cfg = RenderConfig(shake_px=2.0)
    shift = camera_shift(sim, cfg)
    assert not shift[0].any() and np.abs(shift).max() > 1.0
    shaken = [f.astype(float) for f in iter_frames(sim, sensor_noise=0, config=cfg)]
    for f in (20, 40, 59):
        g0, g1 = (np.float32(x.mean(axis=2)[40:-40, 40:-40]) for x in (clean[f], shaken[f]))
        (dx, dy), _ = cv2.phaseCorrelate(g0, g1)
        assert np.hypot(dx - shift[f, 0], dy - shift[f, 1]) < 0.3  # phase correlation: ~0.1-0.25 px
    np.testing.assert_allclose(image_xy(sim, cfg), sim.true_xy + shift[None])
    # motion blur: the fastest frame loses detail near the branch, the static background is unchanged
    blurred = [f.astype(float) for f in iter_frames(sim, sensor_noise=0, config=RenderConfig(exposure=0.5))]
    v = np.hypot(*np.diff(sim.true_xy, axis=1).transpose(2, 0, 1)).max(axis=0)
    f = int(np.argmax(v)) + 1
    changed = np.abs(blurred[f] - clean[f]).sum(axis=2) > 0
    assert 0 < changed.mean() < 0.1
    x0, y0 = np.floor(sim.true_xy[:, f].min(axis=0)).astype(int) - 10
    x1, y1 = np.ceil(sim.true_xy[:, f].max(axis=0)).astype(int) + 10
    lap = [cv2.Laplacian(np.float32(x.mean(axis=2)[y0:y1, x0:x1]), cv2.CV_32F).var() for x in (clean[f], blurred[f])]
    assert lap[1] < 0.9 * lap[0]


def test_simulate_write_with_shake_records_image_positions(tmp_path):
    import json

    import pandas as pd

    from rce_gtsam.sim.nuisance import RenderConfig, camera_shift

    sim = _sim(n_frames=20)
    cfg = RenderConfig(shake_px=1.0, crf=28)
    sim.write(tmp_path / "s", video=True, render=cfg)
    tt = pd.read_csv(tmp_path / "s" / "true_tracks.csv").sort_values(["point_id", "frame"])
    row = {int(n): i for i, n in enumerate(sim.tracks.node_ids)}
    expect = (sim.true_xy + camera_shift(sim, cfg)[None])[[row[p] for p in tt["point_id"]], tt["frame"]]
    np.testing.assert_allclose(tt[["x", "y"]].to_numpy(), expect, atol=1e-4)
    truth = json.loads((tmp_path / "s" / "truth.json").read_text())
    assert truth["render"]["crf"] == 28 and len(truth["render"]["camera_shift_px"]) == 20
