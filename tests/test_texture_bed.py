"""The real-texture test bed (plant 2's frame 0, overlays inpainted, known articulated motion); skips without
``../shared/data`` (the footage is not part of the repository)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rce_gtsam.sim.simulate import turning_angles_deg
from rce_gtsam.sim.texture_bed import angle_floor_deg, clean_first_frame, make_bed, render_frames
from rce_gtsam.track import ArraySource, LKTracker


@pytest.fixture(scope="module")
def bed(shared_data):
    cf = clean_first_frame(shared_data / "plant_2")
    b = make_bed(cf.points, cf.graph, n_frames=60, seed=0, tip_excursion_px=60.0)
    return cf, b


def test_overlays_are_removed_at_the_known_positions(bed):
    cf, _ = bed
    import cv2
    sat = cv2.cvtColor(cf.rgb, cv2.COLOR_RGB2HSV)[..., 1]
    for x, y in np.floor(cf.points).astype(int):
        # the drawn dots are saturated colours; the inpainted stem there is not
        assert np.median(sat[y - 2:y + 3, x - 2:x + 3]) < 150
    assert cf.mask.mean() < 0.08  # only the overlays are inpainted, not the picture


def test_motion_is_the_simulators_on_the_real_chain(bed):
    cf, b = bed
    nodes = list(cf.graph.nodes)
    xy = b.true_xy[nodes]
    # the root is fixed, segment lengths are the real ones, the bends are the scaled simulator response
    assert np.ptp(b.true_xy[cf.graph.root], axis=0).max() < 1e-9
    for p, c in b.edges:
        L0 = np.hypot(*(cf.points[c] - cf.points[p]))
        np.testing.assert_allclose(np.hypot(*(b.true_xy[c] - b.true_xy[p]).T), L0, rtol=1e-9)
    ang = turning_angles_deg(xy, nodes, cf.graph.bends)
    np.testing.assert_allclose(ang - ang[:, :1], b.response_deg, atol=1e-9)
    assert len(b.kappa_true) == len(cf.graph.bends) == 23


@pytest.fixture(scope="module")
def frames(bed):
    cf, b = bed
    return np.stack(list(render_frames(b, cf.rgb, cf.points)))


def test_tracker_follows_the_warped_texture(bed, frames):
    cf, b = bed
    res = LKTracker().track(ArraySource(frames), cf.points, cf.graph)
    err = np.hypot(*(res.xy - b.true_xy).transpose(2, 0, 1))
    assert res.visible.mean() > 0.9
    assert np.median(err[res.visible]) < 0.5


def test_tracker_sigma_is_within_a_factor_of_three_on_real_texture_after_h264(bed, frames, tmp_path):
    """|error| / sigma of the matches anchored to frame 0, after the bed's H.264 (a calibrated 2-D Gaussian gives a
    median of 1.18): the independent-pixel standard error with its 0.05 px floor reads about 1.4 here (2.4 over the
    5-seed, 300-frame bed, record ``track_sigma``; on the simulator's clean renders 0.95). A calibrated sigma for real
    texture (a sandwich standard error and a 0.15 px floor) was measured and not kept: it weakened the smoother on our
    own renders and added false verdicts (commits cc40a21, 6670bac). This guards the factor, not the calibration."""
    from rce_gtsam.sim.render import write_h264
    from rce_gtsam.sim.texture_bed import RenderSettings
    from rce_gtsam.track import open_video

    cf, b = bed
    h, w = frames.shape[1:3]
    path = write_h264(iter(frames), tmp_path / "bed.mp4", fps=30.0, size=(w, h), crf=RenderSettings().crf,
                      pixel_format="rgb24")
    with open_video(path) as src:
        res = LKTracker().track(src, cf.points, cf.graph)
    m = res.visible & (res.info["how"] == 0)
    z = np.hypot(*(res.xy - b.true_xy).transpose(2, 0, 1))[m] / res.sigma_px[m]
    assert 0.4 < np.median(z) < 3.0
    assert np.percentile(z, 90) < 8.0


def test_angle_floor():
    lo, hi = angle_floor_deg(0.2, np.array([20.0]))
    np.testing.assert_allclose(np.radians(lo), np.sqrt(2) * 0.01)
    np.testing.assert_allclose(np.radians(hi), np.sqrt(6) * 0.01)


def test_the_stem_moves_whole_over_a_still_background(bed, frames):
    """limits.md: plant 2's stem is 6.5 px in half-width (the tracker's own measurement on frame 0); the bed moves
    every pixel within ``RenderSettings.inner_px`` = 8 px of the chain rigidly, over a background with the stem
    inpainted out, so the stem's edges move with the stem and no copy of it stays at its frame-0 place."""
    from rce_gtsam.sim.texture_bed import RenderSettings, _seg_dist, still_background

    cf, b = bed
    res = LKTracker().track(ArraySource(frames[:2]), cf.points, cf.graph)
    half = res.info["branch_halfwidth_px"]
    assert half == pytest.approx(6.5) and RenderSettings.inner_px >= half + 1
    limits = " ".join((Path(__file__).resolve().parents[1] / "docs" / "limits.md").read_text().split())
    assert (f"plant 2's stem is {half:g} px in half-width, and the bed moves everything within "
            f"{RenderSettings.inner_px:g} px of its axis") in limits
    # where a node has swung furthest, if no part of the stem is then near its frame-0 place, that place shows the
    # inpainted background, not the stem
    bg = still_background(b, cf.rgb, cf.points).astype(float)
    shown, hidden = [], []
    for node in [c for _, c in b.edges]:
        f = int(np.argmax(np.hypot(*(b.true_xy[node] - b.true_xy[node][:1]).T)))
        x0, y0 = b.true_xy[node, 0]
        near = min(float(_seg_dist(np.array(x0), np.array(y0), b.true_xy[p, f], b.true_xy[c, f]))
                   for p, c in b.edges)
        if near < RenderSettings.outer_px + 4:
            continue
        x, y = np.round(b.true_xy[node, 0]).astype(int)
        win = np.s_[y - 2:y + 3, x - 2:x + 3]
        shown.append(np.abs(frames[f][win].astype(float) - bg[win]).mean())
        hidden.append(np.abs(cf.rgb[win].astype(float) - bg[win]).mean())
    assert len(shown) >= 5
    assert max(shown) < 3  # sensor noise (2 grey levels) and flicker only
    assert np.median(hidden) > 8  # what the stem hid differs from the stem


def test_rendering_some_frames_gives_the_same_frames(bed, frames):
    """``render_frames(only=...)``: the frames asked for are those of a full run (the noise stream is kept)."""
    cf, b = bed
    part = list(render_frames(b, cf.rgb, cf.points, only={3, 40}))
    assert len(part) == len(frames) and part[0] is None and part[39] is None
    np.testing.assert_array_equal(part[3], frames[3])
    np.testing.assert_array_equal(part[40], frames[40])


def test_perfect_rendering_has_nothing_but_the_motion(bed):
    """``RenderSettings.perfect()``: no noise, flicker or blur, lossless. Its frames do not depend on the noise
    stream (another bed seed, the same motion, gives the same frames), and the default bed's differ from them by
    its noise and flicker; the default bed is not perfect."""
    from dataclasses import replace

    from rce_gtsam.sim.texture_bed import RenderSettings

    cf, b = bed
    st = RenderSettings().perfect()
    assert st.is_perfect and st.crf == 0 and not RenderSettings().is_perfect
    a = list(render_frames(b, cf.rgb, cf.points, settings=st, only={0, 30}))
    c = list(render_frames(replace(b, seed=b.seed + 1), cf.rgb, cf.points, settings=st, only={0, 30}))
    np.testing.assert_array_equal(a[30], c[30])
    np.testing.assert_array_equal(a[0], c[0])
    noisy = list(render_frames(b, cf.rgb, cf.points, only={0}))[0]
    # frame 0 of the default bed: the same pose, plus 2 grey levels of noise and a little flicker
    assert 1.5 < np.std(noisy.astype(float) - a[0].astype(float)) < 4.0
