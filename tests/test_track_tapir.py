"""TAPIR ONNX runner against a fake model with the real export's I/O layout (built here with onnx.helper).

The fake predictor's tracks follow the brightest blob, blended with the previous frame's blob centre
carried in ``causal_state``, plus each point's query offset; see tests/track_fixtures.py. So these tests
fail on a wrong resize, normalisation, channel order, (x, y)/(y, x) order, +0.5 pixel convention, or a
causal state that is not fed back.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from rce_gtsam.errors import InputError  # noqa: E402
from rce_gtsam.track import ArraySource  # noqa: E402
from rce_gtsam.track.tapir import TapirOnnxTracker  # noqa: E402

from track_fixtures import blob_video, build_fake_tapir  # noqa: E402


def expected_tracks(q, centres):
    """Fake-model output in original pixels: query offset + 0.5 (c_f + c_{f-1}) (c_0 at frame 0)."""
    c = centres.copy()
    c[1:] = 0.5 * (centres[1:] + centres[:-1])
    return q[:, None, :] + (c - centres[0])[None]


def queries(centres):
    c0 = centres[0]
    return np.array([[c0[0] + 12, c0[1] - 7], [c0[0] - 25, c0[1] + 9], c0, [c0[0] + 3, c0[1] + 15]])


@pytest.mark.parametrize("n_points", ["N", 4, 3])
def test_tracks_follow_blob_in_original_pixels(tmp_path, n_points):
    frames, centres = blob_video(n_frames=14, size=(160, 120))
    model = build_fake_tapir(tmp_path / "m", resolution=64, n_points=n_points)
    q = queries(centres)
    tracker = TapirOnnxTracker(model)
    assert tracker.resolution == 64
    res = tracker.track(ArraySource(frames, fps=20), q)
    assert res.xy.shape == (4, 14, 2) and res.fps == 20
    # point groups: dynamic N -> 1 group; fixed N=4 -> 1; fixed N=3 -> 2 groups (second padded)
    assert res.info["point_groups"] == (2 if n_points == 3 else 1)
    err = np.abs(res.xy - expected_tracks(q, centres))
    assert err.max() < 0.25, err.max()
    assert res.visible.all()
    # the motion is big compared with the tolerance, so following the blob is really tested
    assert np.ptp(res.xy[:, :, 0]) > 50 and np.ptp(res.xy[:, :, 1]) > 30


def test_occlusion_logits_give_visibility_and_sigma(tmp_path):
    frames, centres = blob_video(n_frames=8, size=(160, 120))
    frames[5] = 0  # the blob disappears: the fake model reports occlusion
    model = build_fake_tapir(tmp_path / "m", resolution=64, with_logits=True, expected_dist_logit=-2.0)
    res = TapirOnnxTracker(model).track(ArraySource(frames), queries(centres), max_frames=7)
    assert res.n_frames == 7
    assert not res.visible[:, 5].any() and res.visible[:, [0, 1, 2, 3, 4, 6]].all()
    u = 1 / (1 + np.exp(2.0))
    sigma_model = 6.0 * 64 / 256 / np.sqrt(-2 * np.log(u))
    np.testing.assert_allclose(res.sigma_px, sigma_model * 160 / 64, rtol=1e-5)


def test_wrong_signature_is_a_clear_error(tmp_path):
    model = build_fake_tapir(tmp_path / "m", rename={"tracks": "points", "causal_state": "state"})
    with pytest.raises(InputError) as e:
        TapirOnnxTracker(model)
    msg = str(e.value)
    assert "tapir.onnx" in msg and "'tracks'" in msg and "'causal_state'" in msg and "Found" in msg


def test_missing_model_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        TapirOnnxTracker(tmp_path / "nothing")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "tapir.onnx").write_bytes(b"x")
    with pytest.raises(InputError, match="tapir_pointencoder.onnx"):
        TapirOnnxTracker(tmp_path / "d")


def test_export_tool_help_runs_without_torch():
    import subprocess
    import sys
    from pathlib import Path

    tool = Path(__file__).resolve().parents[1] / "tools" / "export_tapir_onnx.py"
    out = subprocess.run([sys.executable, str(tool), "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "NOT RUN IN CI" in out.stdout and "torch" in out.stdout
