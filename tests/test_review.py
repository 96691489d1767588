"""`rce review VIDEO TRACKS.csv`: re-tracking from corrections (track/anchors.py), its bad inputs, and the page in
Debian's chromium driven by Selenium (as tests/test_annotate_browser.py does): a real drag corrects one node in one
frame, Re-track refits its track, Save writes the files, and `rce track --corrections` reproduces them."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import _branch_video as bv
from rce_gtsam.cli.app import main
from rce_gtsam.graph import load_graph
from rce_gtsam.track import LKTracker
from rce_gtsam.track.anchors import Correction, DenseTracks, FrameStore, retrack
from rce_gtsam.tracks import read_tracks_table
from _browser import chromium_driver

N_FRAMES = 36
K = 18          # the corrected frame
NODE = 4        # the corrected node (the tip)
SHIFT_PX = 7.0  # the correction: this far from the tracked tip toward node 3, along the stem
SCREENSHOT_DIR = os.environ.get("RCE_ANNOTATE_SCREENSHOT_DIR")  # set to keep the page's screenshot


def _rce(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rce_gtsam.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=120)


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> dict:
    """The clip, its annotation and graph, and `rce track`'s tracks of it (the tracks a user reviews)."""
    d = tmp_path_factory.mktemp("review")
    video = bv.write_video(d / "branch.mp4", N_FRAMES)
    ann, graph = d / "annotations.json", d / "graph.json"
    ann.write_text(json.dumps({"points": bv.NODES.tolist()}))
    graph.write_text(json.dumps({"root": 0, "edges": [[i, i + 1] for i in range(len(bv.NODES) - 1)]}))
    tracks = d / "tracks.csv"
    r = _rce("track", video, ann, "--graph", graph, "--out", tracks, "--no-progress")
    assert r.returncode == 0, r.stderr
    return {"dir": d, "video": video, "annotations": ann, "graph": graph, "tracks": tracks}


def _along_stem(xy_tip, xy_prev, shift):
    d = np.asarray(xy_prev) - np.asarray(xy_tip)
    return np.asarray(xy_tip) + shift * d / np.linalg.norm(d)


def test_retrack_follows_a_correction_and_is_idempotent(scene):
    """The corrected frame equals the correction; the frames after it follow the corrected stem point (its true
    path is known: the branch turns rigidly about its root); frames before it move toward it, less with distance;
    other nodes keep their rows; re-tracking the re-tracked tracks gives the same tracks."""
    base = DenseTracks.from_table(read_tracks_table(scene["tracks"]))
    graph = load_graph(scene["graph"])
    target = _along_stem(base.xy[NODE, K], base.xy[NODE - 1, K], SHIFT_PX)
    corr = [Correction(K, NODE, float(target[0]), float(target[1]))]
    with FrameStore(scene["video"], base.n_frames) as store:
        out, first = retrack(store, base, corr, LKTracker(), graph)
        again, _ = retrack(store, out, corr, LKTracker(), graph, first_run=first)
    assert np.array_equal(out.xy[NODE, K], target)
    p0 = bv.rotate(target[None], -bv.angle(K))[0]              # the corrected point in frame 0
    truth = bv.true_positions(p0[None], N_FRAMES)[0]
    after = np.hypot(*(out.xy[NODE, K:] - truth[K:]).T)
    assert after.max() < 0.5, f"after the correction the tip follows the corrected point to {after.round(2)} px"
    moved = np.hypot(*(out.xy[NODE] - base.xy[NODE]).T)
    assert moved[K - 1] > 0.8 * SHIFT_PX and moved[K - 1] > moved[K // 2] > moved[1] and moved[0] < 1e-9
    assert np.array_equal(out.xy[:NODE], base.xy[:NODE]) and np.array_equal(out.sigma_px[:NODE], base.sigma_px[:NODE])
    assert (out.visible | ~base.visible).all()                  # re-tracking drops no point-frame that was seen
    assert np.array_equal(again.xy, out.xy) and np.array_equal(again.sigma_px, out.sigma_px)


@pytest.mark.parametrize("case", ["no-video", "no-tracks", "unknown-node", "beyond-video", "outside-frame",
                                  "track-unknown-node", "track-missing"])
def test_bad_input_is_one_line_and_exit_2(scene, tmp_path, capsys, case):
    bad = tmp_path / "c.json"
    item = {"frame": 3, "node": 2, "x": 100.0, "y": 100.0}
    item.update({"unknown-node": {"node": 9}, "track-unknown-node": {"node": 9}, "beyond-video": {"frame": N_FRAMES},
                 "outside-frame": {"x": 400.0}}.get(case, {}))
    bad.write_text(json.dumps({"corrections": [item]}))
    video, tracks = scene["video"], scene["tracks"]
    if case == "no-video":
        argv = ["review", tmp_path / "none.mp4", tracks]
    elif case == "no-tracks":
        argv = ["review", video, tmp_path / "none.csv"]
    elif case.startswith("track-"):
        argv = ["track", video, scene["annotations"], "--out", tmp_path / "t.csv", "--no-progress",
                "--corrections", bad if case != "track-missing" else tmp_path / "none.json"]
    else:
        argv = ["review", video, tracks, "--corrections", bad, "--no-browser"]
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    want = {"no-video": "video file not found", "no-tracks": "tracks file not found", "unknown-node": "node 9",
            "beyond-video": f"frame {N_FRAMES} is beyond the video", "outside-frame": "outside the 320x240 frame",
            "track-unknown-node": "node 9", "track-missing": "corrections file not found"}[case]
    assert want in err[0], err[0]
    assert not (tmp_path / "t.csv").exists()


# ---------------------------------------------------------------------------------------------- the page
@pytest.fixture(scope="module")
def browser():
    drv = chromium_driver(1280, 800)
    yield drv
    drv.quit()


def _wait(drv, script: str, timeout: float = 20.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        v = drv.execute_script(script)
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for: {script}; status: {drv.find_element('id', 'status').text}")


@pytest.mark.slow
def test_page_drag_retrack_save_and_reproduce(scene, tmp_path, browser):
    from selenium.webdriver import ActionChains

    d = tmp_path / "run"
    d.mkdir()
    tracks = d / "tracks.csv"
    shutil.copyfile(scene["tracks"], tracks)
    proc = subprocess.Popen([sys.executable, "-m", "rce_gtsam.cli", "review", str(scene["video"]), str(tracks),
                             "--annotations", str(scene["annotations"]), "--graph", str(scene["graph"]),
                             "--no-browser"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:\d+/", line)
        assert m, f"no URL printed: {line!r} {proc.stderr.read() if proc.poll() is not None else ''}"
        drv = browser
        drv.get(m.group(0))
        _wait(drv, "return window.rce && window.rce.ready")
        canvas = drv.find_element("id", "view")
        # scrub with the keyboard to the frame to correct
        canvas.click()
        for _ in range(K):
            ActionChains(drv).send_keys("\ue014").perform()     # ArrowRight
        _wait(drv, f"return window.rce.frameShown === {K}")
        before = np.array([drv.execute_script("return window.rce.position(arguments[0], arguments[1])", NODE, f)[:2]
                           for f in range(N_FRAMES)], float)
        prev = drv.execute_script("return window.rce.position(arguments[0], arguments[1])", NODE - 1, K)[:2]
        target = _along_stem(before[K], prev, SHIFT_PX)

        def offset(x, y):
            cx, cy = drv.execute_script("return window.rce.toClient(arguments[0], arguments[1])", x, y)
            r = canvas.rect
            return round(cx - (r["x"] + r["width"] / 2)), round(cy - (r["y"] + r["height"] / 2))

        (dx0, dy0), (dx1, dy1) = offset(*before[K]), offset(*target)
        (ActionChains(drv).move_to_element_with_offset(canvas, dx0, dy0).click_and_hold()
         .move_by_offset((dx1 - dx0) // 2, (dy1 - dy0) // 2)
         .move_by_offset(dx1 - dx0 - (dx1 - dx0) // 2, dy1 - dy0 - (dy1 - dy0) // 2).release().perform())
        st = drv.execute_script("return window.rce.state()")
        assert len(st["corrections"]) == 1 and st["stale"], st
        c = st["corrections"][0]
        assert (c["frame"], c["node"]) == (K, NODE)
        corrected = np.array([c["x"], c["y"]])
        assert np.hypot(*(corrected - target)) < 1.0, (corrected, target)   # the drag landed where it was aimed
        drv.find_element("id", "retrack").click()
        _wait(drv, "return window.rce.pending === 0 && !window.rce.state().stale")
        after = np.array([drv.execute_script("return window.rce.position(arguments[0], arguments[1])", NODE, f)[:2]
                          for f in range(N_FRAMES)], float)
        assert np.allclose(after[K], corrected)
        toward = (after - before) @ ((corrected - before[K]) / np.hypot(*(corrected - before[K])))
        assert toward[K - 1] > 0.8 * SHIFT_PX and toward[K + 1] > 0.8 * SHIFT_PX, toward.round(2)
        assert toward[K - 1] > toward[K // 2] > toward[1] and abs(toward[0]) < 1e-6, toward.round(2)
        flags = drv.find_elements("css selector", "#flags li")
        assert flags, "the flagged-frames list is empty"
        if SCREENSHOT_DIR:
            drv.save_screenshot(str(Path(SCREENSHOT_DIR) / "review.png"))
        drv.find_element("id", "finish").click()
        _wait(drv, "return !document.getElementById('next-command').hidden")
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(10)
    saved = json.loads((d / "tracks.corrections.json").read_text())["corrections"]
    assert saved == [{"frame": K, "node": NODE, "x": c["x"], "y": c["y"]}]
    assert (d / "tracks.csv.bak").read_bytes() == scene["tracks"].read_bytes()
    t = pd.read_csv(tracks)
    xy = t[t.point_id == NODE].sort_values("frame")[["x", "y"]].to_numpy()
    assert np.allclose(xy, after, atol=1e-3)
    assert "reproduce: rce track" in out
    # the printed command gives the same tracks from the video, the annotation and the corrections
    again = d / "again.csv"
    r = _rce("track", scene["video"], scene["annotations"], "--graph", scene["graph"], "--out", again,
             "--corrections", d / "tracks.corrections.json", "--no-progress")
    assert r.returncode == 0, r.stderr
    assert again.read_bytes() == tracks.read_bytes()
