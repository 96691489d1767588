"""`rce annotate VIDEO` in a real browser: Debian's chromium driven by Selenium through chromium-driver.

The CLI runs as a subprocess serving its page; the test clicks at given image positions on the rendered
frame (real pointer events), then checks the files the page made the CLI write. Nothing is downloaded:
the browser and its driver are system packages (`make test` installs them as root).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from _browser import chromium_driver

# A branch on a 320 x 240 frame (px): main chain 0-1-2-3-4 and a side branch 2-5-6.
MAIN = [(60.0, 210.0), (98.0, 172.0), (136.0, 134.0), (172.0, 100.0), (206.0, 64.0)]
SIDE = [(182.0, 150.0), (226.0, 162.0)]
SCREENSHOT_DIR = os.environ.get("RCE_ANNOTATE_SCREENSHOT_DIR")  # set to keep the page's screenshot


def _draw_branch(frame: np.ndarray, shift: float) -> None:
    brown = (45, 75, 115)  # BGR, the simulator's bark colour
    pts = [(x + shift, y) for x, y in MAIN]
    side = [pts[2]] + [(x + shift, y) for x, y in SIDE]
    for poly, width in ((pts, 9), (side, 7)):
        for (ax, ay), (bx, by) in zip(poly[:-1], poly[1:]):
            # cv2 draws with 4 fractional bits: pixel centres are integer coordinates, as in rce
            cv2.line(frame, (round(ax * 16), round(ay * 16)), (round(bx * 16), round(by * 16)), brown, width,
                     cv2.LINE_AA, shift=4)


@pytest.fixture(scope="module")
def branch_video(tmp_path_factory) -> Path:
    """A 6-frame mp4 of the branch over a textured green background, swaying a few pixels."""
    path = tmp_path_factory.mktemp("video") / "branch.mp4"
    rng = np.random.default_rng(0)
    noise = cv2.GaussianBlur(rng.normal(0, 1, (240, 320)).astype(np.float32), (0, 0), 6)
    bg = np.clip(np.dstack([100 + 40 * noise, 130 + 40 * noise, 110 + 30 * noise]), 0, 255).astype(np.uint8)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 30, (320, 240))
    for f in range(6):
        frame = bg.copy()
        _draw_branch(frame, shift=2.0 * np.sin(f))
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def browser():
    drv = chromium_driver(1100, 800)
    yield drv
    drv.quit()


class Page:
    """The annotate page in the browser, with clicks given in image pixels."""

    def __init__(self, drv, url: str):
        self.drv = drv
        drv.get(url)
        self.wait("return window.rce && window.rce.ready")
        self.canvas = drv.find_element("id", "view")

    def wait(self, script: str, timeout: float = 15.0):
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            v = self.drv.execute_script(script)
            if v:
                return v
            time.sleep(0.05)
        raise AssertionError(f"timed out waiting for: {script}; status: {self.status()}")

    def status(self) -> str:
        return self.drv.find_element("id", "status").text

    def state(self) -> dict:
        return self.drv.execute_script("return window.rce.state()")

    def _offset(self, x: float, y: float) -> tuple[int, int]:
        cx, cy = self.drv.execute_script("return window.rce.toClient(arguments[0], arguments[1])", x, y)
        r = self.canvas.rect
        return round(cx - (r["x"] + r["width"] / 2)), round(cy - (r["y"] + r["height"] / 2))

    def click(self, x: float, y: float) -> None:
        from selenium.webdriver import ActionChains
        n_before = len(self.state()["points"])
        dx, dy = self._offset(x, y)
        ActionChains(self.drv).move_to_element_with_offset(self.canvas, dx, dy).click().perform()
        self.wait(f"return window.rce.pending === 0 && window.rce.state().points.length > {n_before}")

    def select(self, node: int) -> None:
        from selenium.webdriver import ActionChains
        x, y = self.state()["points"][node]
        dx, dy = self._offset(x, y)
        ActionChains(self.drv).move_to_element_with_offset(self.canvas, dx, dy).click().perform()
        self.wait(f"return window.rce.state().selected === {node}")

    def drag(self, node: int, to: tuple[float, float]) -> None:
        from selenium.webdriver import ActionChains
        x, y = self.state()["points"][node]
        dx0, dy0 = self._offset(x, y)
        dx1, dy1 = self._offset(*to)
        (ActionChains(self.drv).move_to_element_with_offset(self.canvas, dx0, dy0).click_and_hold()
         .move_by_offset((dx1 - dx0) // 2, (dy1 - dy0) // 2).move_by_offset(dx1 - dx0 - (dx1 - dx0) // 2,
                                                                               dy1 - dy0 - (dy1 - dy0) // 2)
         .release().perform())
        self.wait("return window.rce.pending === 0")

    def button(self, name: str) -> None:
        self.drv.find_element("id", name).click()


@pytest.fixture()
def annotate(branch_video, tmp_path, browser):
    """Start `rce annotate VIDEO --out DIR --no-browser`; yield (Page, out dir, process)."""
    out = tmp_path / "ann"
    proc = subprocess.Popen([sys.executable, "-m", "rce_gtsam.cli", "annotate", str(branch_video), "--out", str(out),
                             "--no-browser"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:\d+/", line)
        assert m, f"no URL printed: {line!r} {proc.stderr.read() if proc.poll() is not None else ''}"
        yield Page(browser, m.group(0)), out, proc
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(10)


def _across(i: int, pts, off: float) -> tuple[float, float]:
    """``pts[i]`` moved ``off`` px perpendicular to its segment (a sloppy click beside the stem)."""
    a, b = np.array(pts[max(i - 1, 0)]), np.array(pts[max(i, 1)])
    d = (b - a) / np.linalg.norm(b - a)
    p = np.array(pts[i]) + off * np.array([-d[1], d[0]])
    return float(p[0]), float(p[1])


def _finish(page: Page, proc) -> str:
    page.button("finish")
    page.wait("return !document.getElementById('next-command').hidden")
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    return out


@pytest.mark.slow
def test_chain_clicks_snap_to_the_stem_and_write_files(annotate):
    page, out, proc = annotate
    for i in range(len(MAIN)):
        page.click(*_across(i, MAIN, 3.0 if i % 2 else -3.0))  # 3 px off the centre line, alternating sides
    st = page.state()
    assert st["edges"] == [[0, 1], [1, 2], [2, 3], [3, 4]]
    if SCREENSHOT_DIR:
        page.drv.save_screenshot(str(Path(SCREENSHOT_DIR) / "annotate_chain.png"))
    stdout = _finish(page, proc)
    pts = np.array(json.loads((out / "annotations.json").read_text())["points"])
    err = np.hypot(*(pts - np.array(MAIN)).T)
    assert err.max() < 1.0, f"clicks 3 px off the stem snapped to within {err.round(2)} px of its centre line"
    graph = json.loads((out / "graph.json").read_text())
    assert graph["root"] == 0 and graph["edges"] == [[0, 1], [1, 2], [2, 3], [3, 4]]
    nxt = page.drv.find_element("id", "next-command").text
    assert " run " in nxt and str(out / "annotations.json") in nxt and str(out / "graph.json") in nxt
    assert "next: " in stdout and " run " in stdout.split("next: ", 1)[1]


@pytest.mark.slow
def test_branched_graph_with_drag_and_undo(annotate):
    page, out, proc = annotate
    page.click(*MAIN[0])
    page.click(*MAIN[1])
    page.button("save")                                 # two nodes have no bend: refused, nothing written
    page.wait("return document.getElementById('status').classList.contains('error')")
    assert "at least 3 nodes" in page.status()
    assert not (out / "annotations.json").exists()
    for i in range(2, len(MAIN)):
        page.click(*MAIN[i])
    page.select(2)                                      # click an existing node: the side branch starts there
    assert "side branch" in page.status()
    for p in SIDE:
        page.click(*p)
    st = page.state()
    assert st["edges"] == [[0, 1], [1, 2], [2, 3], [3, 4], [2, 5], [5, 6]]
    before = st["points"][6]
    page.drag(6, (before[0] + 20, before[1] + 25))      # drag a node away ...
    moved = page.state()["points"][6]
    assert np.hypot(moved[0] - before[0], moved[1] - before[1]) > 10
    page.button("undo")                                 # ... and undo it
    assert page.state()["points"][6] == before
    page.button("undo")                                 # undo the last click: node 6 is gone
    assert len(page.state()["points"]) == 6
    page.click(*SIDE[1])
    # a slider move shows another frame; editing is on frame 0 only
    page.drv.execute_script("const s = document.getElementById('frame'); s.value = 3; s.oninput();")
    page.wait("return window.rce.frameShown === 3")
    if SCREENSHOT_DIR:
        page.drv.execute_script("const s = document.getElementById('frame'); s.value = 0; s.oninput();")
        page.wait("return window.rce.frameShown === 0")
        page.drv.save_screenshot(str(Path(SCREENSHOT_DIR) / "annotate_branched.png"))
    _finish(page, proc)
    graph = json.loads((out / "graph.json").read_text())
    assert graph["edges"] == [[0, 1], [1, 2], [2, 3], [3, 4], [2, 5], [5, 6]]
    pts = np.array(json.loads((out / "annotations.json").read_text())["points"])
    err = np.hypot(*(pts - np.array(MAIN + SIDE)).T)
    assert err.max() < 1.0, err.round(2)
