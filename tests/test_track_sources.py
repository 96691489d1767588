"""Frame sources and annotations: mp4 and RealSense round trips, clear errors, polyline node placement."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rce_gtsam.errors import InputError
from rce_gtsam.track import (ArraySource, load_annotations, open_video, parse_polyline, place_nodes_along_polyline,
                             write_annotation_files)
from rce_gtsam.track.sources import RealSenseSource, VideoFileSource

from track_fixtures import blob_video, record_realsense, write_mp4


def test_mp4_round_trip_is_rgb_and_streams(tmp_path):
    frames, _ = blob_video(n_frames=6, size=(96, 64))
    frames[:, :, :, 1] //= 2  # distinct channels: a BGR/RGB mix-up changes the pixel values
    frames[:, :, :, 2] = 40
    path = write_mp4(frames, tmp_path / "v.mp4", fps=25)
    with open_video(path) as src:
        assert isinstance(src, VideoFileSource)
        assert src.size == (96, 64) and src.fps == pytest.approx(25) and src.n_frames == 6
        got = list(src)
    assert [f.index for f in got] == list(range(6))
    assert got[3].timestamp_s == pytest.approx(3 / 25)
    for f, ref in zip(got, frames):
        assert f.image.shape == (64, 96, 3) and f.image.dtype == np.uint8
        assert np.abs(f.image.astype(int) - ref).mean() < 1.5  # lossless H.264, 4:4:4, up to YUV rounding


def test_missing_and_unreadable_video(tmp_path):
    with pytest.raises(InputError, match="not found"):
        open_video(tmp_path / "nope.mp4")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"this is not a video" * 10)
    with pytest.raises(InputError, match="bad.mp4"):
        open_video(bad)


def test_realsense_db3_round_trip(tmp_path):
    # exc_type=ImportError: a missing libusb-1.0.so.0 is an ImportError, not ModuleNotFoundError
    pytest.importorskip("pyrealsense2", exc_type=ImportError,
                        reason="pyrealsense2 cannot import (needs apt libusb-1.0-0; `make test` installs it as root)")
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(7)]
    path = record_realsense(tmp_path / "rec.db3", frames, fps=30)
    with open_video(path) as src:
        assert isinstance(src, RealSenseSource)
        assert src.size == (64, 48) and src.fps == 30
        got = list(src)
    assert len(got) == len(frames)
    for f, ref in zip(got, frames):
        np.testing.assert_array_equal(f.image, ref)
    np.testing.assert_allclose([f.timestamp_s for f in got], np.arange(7) / 30, atol=1e-6)


def test_realsense_missing_dependency_message(monkeypatch, tmp_path):
    import builtins

    from rce_gtsam.errors import MissingDependencyError

    real_import = builtins.__import__

    def fake_import(name, *a, **k):
        if name == "pyrealsense2":
            raise ImportError("libusb-1.0.so.0: cannot open shared object file")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    f = tmp_path / "x.bag"
    f.write_bytes(b"0" * 10)
    with pytest.raises(MissingDependencyError, match="libusb-1.0-0") as e:
        open_video(f)
    assert "rce_gtsam[realsense]" in str(e.value)


def test_array_source_validates():
    with pytest.raises(InputError):
        ArraySource(np.zeros((2, 4, 4), np.uint8))


def test_load_annotations_validates(tmp_path):
    p = tmp_path / "a.json"
    p.write_text(json.dumps({"points": [[1.5, 2], [10, 20]]}))
    np.testing.assert_array_equal(load_annotations(p), [[1.5, 2], [10, 20]])
    with pytest.raises(InputError, match=r"point 1.*outside the 16x12 image"):
        load_annotations(p, image_size=(16, 12))
    for text, msg in [("{", "not valid JSON"), ('{"pts": []}', "points"), ('{"points": [[1, 2, 3]]}', r"\[x, y\]"),
                      ('{"points": []}', "non-empty"), ('{"points": [[1, "a"]]}', "number")]:
        p.write_text(text)
        with pytest.raises(InputError, match=msg):
            load_annotations(p)
    with pytest.raises(InputError, match="not found"):
        load_annotations(tmp_path / "missing.json")


def test_polyline_nodes_are_evenly_spaced_and_files_round_trip(tmp_path):
    poly = parse_polyline("0,0, 30,0, 30,40")  # length 70, corner at 30
    pts, graph = place_nodes_along_polyline(poly, 8)
    np.testing.assert_allclose(pts[0], [0, 0])
    np.testing.assert_allclose(pts[-1], [30, 40])
    np.testing.assert_allclose(pts[3], [30, 0])  # arc length 30 = 3 * 10
    # every node is at arc length 10 * i: consecutive straight-line gaps are 10 except across the corner
    gaps = np.hypot(*np.diff(pts, axis=0).T)
    np.testing.assert_allclose(np.delete(gaps, [2, 3]), 10.0)
    assert graph.root == 0 and graph.edges == tuple((i, i + 1) for i in range(7))
    a, g = tmp_path / "ann.json", tmp_path / "graph.json"
    write_annotation_files(pts, graph, a, g)
    np.testing.assert_allclose(load_annotations(a), pts, atol=1e-3)
    assert json.loads(g.read_text()) == {"root": 0, "edges": [[i, i + 1] for i in range(7)]}
    with pytest.raises(InputError):
        parse_polyline("1,2,3")
    with pytest.raises(InputError):
        place_nodes_along_polyline(poly, 1)
