"""The annotate server's pieces without a browser: snapping, saving (validation, files), resuming, frames."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from rce_gtsam.annotate_web import AnnotationSession, RidgeSnapper
from rce_gtsam.errors import InputError


def _stem_image(y_centre: float = 30.0, width: int = 8) -> np.ndarray:
    img = np.full((60, 120, 3), (110, 140, 120), np.uint8)
    y16 = round(y_centre * 16)
    cv2.line(img, (10 * 16, y16), (110 * 16, y16), (115, 75, 45), width, cv2.LINE_AA, shift=4)
    return img


@pytest.mark.parametrize("off", [-4.0, -2.5, 2.0, 4.0])
def test_snap_moves_a_click_across_onto_the_centre_line_only(off):
    r = RidgeSnapper(_stem_image(30.0)).snap(50.3, 30.0 + off)
    assert r.snapped and abs(r.y - 30.0) < 0.3 and r.x == pytest.approx(50.3, abs=1e-6)  # along the stem: kept


def test_snap_leaves_a_click_far_from_any_stem_alone():
    r = RidgeSnapper(_stem_image(30.0), radius_px=6).snap(60.0, 50.0)  # 20 px from the stem
    assert not r.snapped and (r.x, r.y) == (60.0, 50.0)


@pytest.fixture()
def video(tmp_path):
    path = tmp_path / "v.mp4"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 30, (120, 60))
    for _ in range(3):
        w.write(_stem_image()[..., ::-1].copy())
    w.release()
    return path


def test_save_writes_a_tree_and_the_next_command_and_a_new_session_resumes_it(video, tmp_path, monkeypatch):
    fake_bin = tmp_path / "bin"  # rce on PATH (an activated environment): the next command says plain rce
    fake_bin.mkdir()
    (fake_bin / "rce").write_text("#!/bin/sh\n")
    (fake_bin / "rce").chmod(0o755)
    monkeypatch.setenv("PATH", str(fake_bin))
    s = AnnotationSession(video, tmp_path / "ann")
    pts = [[15.0, 30.0], [50.0, 30.0], [90.0, 30.0], [70.0, 40.0]]
    out = s.save({"points": pts, "edges": [[0, 1], [1, 2], [1, 3]], "root": 0})
    assert out["n_nodes"] == 4 and out["n_bends"] == 2
    assert out["next"].startswith(f"rce run {video} {tmp_path / 'ann' / 'annotations.json'}")
    assert json.loads((tmp_path / "ann" / "graph.json").read_text()) == {"root": 0, "edges": [[0, 1], [1, 2], [1, 3]]}
    s.close()
    again = AnnotationSession(video, tmp_path / "ann")
    prev = again.info()["previous"]
    assert prev == {"points": pts, "edges": [[0, 1], [1, 2], [1, 3]]}
    k, jpeg = again.frames.get(99)  # past the end: the last frame
    assert k == 2 and jpeg[:2] == b"\xff\xd8"
    again.close()


@pytest.mark.parametrize("payload, message", [
    ({"points": [[1, 1], [2, 2]], "edges": [[0, 1]]}, "at least 3 nodes"),
    ({"points": [[1, 1], [2, 2], [3, 3]], "edges": [[0, 1], [2, 1]]}, "node 1 has two parents"),
    ({"points": [[1, 1], [2, 2], [3, 3], [4, 4]], "edges": [[0, 1], [1, 2]]}, "node 3 is not connected"),
    ({"points": [[1, 1], [2, 2], [300, 3]], "edges": [[0, 1], [1, 2]]}, "outside the 120x60 image"),
])
def test_save_refuses_what_the_tracker_cannot_use(video, tmp_path, payload, message):
    s = AnnotationSession(video, tmp_path / "ann")
    with pytest.raises(InputError, match=message):
        s.save(payload)
    assert not (tmp_path / "ann").exists()
    s.close()


def test_the_next_command_names_the_running_executable_when_rce_is_not_on_path(video, tmp_path, monkeypatch):
    """Without an activated environment ``rce`` is not on PATH: the printed next command must still run, so it
    starts with the path of what is running (this interpreter with -m rce_gtsam.cli, or .venv/bin/rce)."""
    import os
    import shlex
    import sys
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    s = AnnotationSession(video, tmp_path / "ann")
    pts = [[15.0, 30.0], [50.0, 30.0], [90.0, 30.0], [70.0, 40.0]]
    argv = shlex.split(s.save({"points": pts, "edges": [[0, 1], [1, 2], [1, 3]], "root": 0})["next"])
    s.close()
    assert argv[0] != "rce" and os.path.isabs(argv[0]) and os.access(argv[0], os.X_OK), argv
    if argv[0] == sys.executable:
        assert argv[1:4] == ["-m", "rce_gtsam.cli", "run"], argv
    assert argv[argv.index("run") + 1] == str(video)
