"""RealSense recordings with depth: the writer's .db3 plays back in pyrealsense2 with both streams, exact pixels,
the registered intrinsics, and a working rs.align; RealSenseDepthSource yields the depth with each colour frame."""

from __future__ import annotations

import numpy as np
import pytest

from rce_gtsam.camera import CameraIntrinsics
from rce_gtsam.errors import InputError

rs = pytest.importorskip("pyrealsense2", exc_type=ImportError,
                         reason="pyrealsense2 cannot import (needs apt libusb-1.0-0; `make test` installs it as root)")

from rce_gtsam.sim.realsense_writer import write_recording  # noqa: E402
from rce_gtsam.track.depth import RealSenseDepthSource, recording_has_depth  # noqa: E402

CAM = CameraIntrinsics(160, 120, 154.0, 153.0, 80.5, 59.5)
T = 12


def _frames():
    rng = np.random.default_rng(3)
    color = rng.integers(0, 256, (T, CAM.height, CAM.width, 3), dtype=np.uint8)
    yy, xx = np.mgrid[0:CAM.height, 0:CAM.width]
    depth = np.repeat((700 + xx + 2 * yy).astype(np.uint16)[None], T, axis=0)
    depth[:, 40, 50] = 1000 + np.arange(T)  # a marked pixel per frame
    depth[:, 10:14, 20:24] = 0              # a hole
    return color, depth


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    color, depth = _frames()
    path = write_recording(tmp_path_factory.mktemp("rs") / "rec.db3", color, depth, CAM, fps=30)
    return path, color, depth


def test_writer_plays_back_with_pyrealsense2(recording):
    path, color, depth = recording
    assert not list(path.parent.glob(".*partial*"))  # the temporary name is gone
    pipe = rs.pipeline()
    cfg = rs.config()
    cfg.enable_device_from_file(str(path), repeat_playback=False)
    profile = pipe.start(cfg)
    profile.get_device().as_playback().set_real_time(False)
    assert profile.get_device().first_depth_sensor().get_depth_scale() == pytest.approx(0.001)
    intr = profile.get_stream(rs.stream.depth).as_video_stream_profile().get_intrinsics()
    assert (intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy) == (160, 120, 154.0, 153.0, 80.5, 59.5)
    align = rs.align(rs.stream.color)
    seen = []
    try:
        while True:
            ok, fs = pipe.try_wait_for_frames(2000)
            if not ok:
                break
            c, d = fs.get_color_frame(), fs.get_depth_frame()
            n = c.get_frame_number()
            assert d.get_frame_number() == n
            assert np.array_equal(np.asanyarray(c.get_data()), color[n])
            assert np.array_equal(np.asanyarray(d.get_data()), depth[n])  # every pixel's depth round-trips exactly
            aligned = align.process(fs).get_depth_frame()
            assert aligned and aligned.get_width() == CAM.width
            a = np.asanyarray(aligned.get_data()).astype(int)
            valid = (a > 0) & (depth[n] > 0)
            assert valid.mean() > 0.9  # rs.align leaves scattered rounding holes, ~2-5 % of pixels
            err = np.abs(a - depth[n])[valid]  # registered streams: align moves nothing (up to a pixel of rounding)
            assert np.median(err) == 0 and np.quantile(err, 0.99) <= 2
            seen.append(n)
    finally:
        pipe.stop()
    # rs.pipeline drops frames of a short recording when the machine is busy (9 of 12 seen once, in a CI run beside
    # other work); every frame it does deliver must round-trip exactly. RealSenseDepthSource reads all (below).
    assert len(seen) >= T // 2 and seen == sorted(seen)


def test_depth_source_yields_depth_with_each_colour_frame(recording):
    path, color, depth = recording
    assert recording_has_depth(path)
    with RealSenseDepthSource(path) as src:
        assert src.intrinsics == CAM and src.size == (160, 120) and src.fps == pytest.approx(30)
        assert src.aligned_by == "registered" and src.depth_unit_mm == pytest.approx(1.0, abs=1e-6)
        got = list(src)
    assert [f.index for f in got] == list(range(T))
    assert got[5].timestamp_s == pytest.approx(5 / 30, abs=1e-6)
    for f in got:
        assert np.array_equal(f.image, color[f.index])
        assert f.depth_mm.dtype == np.float32 and f.depth_mm[40, 50] == pytest.approx(1000 + f.index, abs=1e-3)
        assert np.all(f.depth_mm[10:14, 20:24] == 0)


def test_colour_only_recording_has_no_depth(tmp_path):
    from track_fixtures import record_realsense

    frames = np.zeros((3, 24, 32, 3), np.uint8)
    path = record_realsense(tmp_path / "c.db3", frames)
    assert not recording_has_depth(path)
    assert not recording_has_depth(tmp_path / "video.mp4")


def test_writer_rejects_bad_input_before_writing(tmp_path):
    color, depth = _frames()
    with pytest.raises(InputError, match="db3"):
        write_recording(tmp_path / "x.bag", color, depth, CAM)
    with pytest.raises(InputError, match="uint16"):
        write_recording(tmp_path / "x.db3", color, depth.astype(np.float32), CAM)
    with pytest.raises(InputError, match="intrinsics are for"):
        write_recording(tmp_path / "x.db3", color, depth, CameraIntrinsics.d435i_colour())
    assert not list(tmp_path.iterdir())


def test_register_depth_moves_depth_by_the_extrinsics():
    from rce_gtsam.track.depth import register_depth

    depth = np.zeros((CAM.height, CAM.width), np.float32)
    depth[60, 80] = 800.0
    # colour camera 15 mm to the left of the depth camera: points appear 15 mm further right, same z
    out = register_depth(depth, CAM, CAM, np.eye(3), np.array([15.0, 0.0, 0.0]))
    v, u = np.nonzero(out)
    assert (v.tolist(), out[v, u].tolist()) == ([60], [800.0])
    assert u[0] == round(CAM.fx * (80 - CAM.cx) / CAM.fx + CAM.cx + CAM.fx * 15.0 / 800.0)
