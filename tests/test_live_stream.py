"""`rce track` / `rce run` --connect: stream live into a real, viewer-less Rerun gRPC server and read it back.

The sink is this environment's `rerun` binary run as `rerun --bind 127.0.0.1 --port P --save sink.rrd`: a
gRPC server that writes everything SDKs send it to an .rrd (no window). After the command it is stopped and
its file is read with `rerun.chunk.RrdReader`.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rce_gtsam.cli import main


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Sink:
    def __init__(self, path: Path):
        from rce_gtsam.viewer import viewer_executable
        self.path, self.port = path, _free_port()
        self.proc = subprocess.Popen([viewer_executable(), "--bind", "127.0.0.1", "--port", str(self.port),
                                      "--save", str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True)  # its own group: the wrapper's child dies with it
        t0 = time.monotonic()
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=1).close()
                break
            except OSError:
                assert self.proc.poll() is None and time.monotonic() - t0 < 20, "the rerun gRPC sink did not start"
                time.sleep(0.1)

    def signal_group(self, sig) -> None:
        """Send ``sig`` to the sink's process group (the rerun wrapper and the viewer binary it starts)."""
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def stop(self) -> list:
        """Stop the server and return its chunks, in the order they arrived."""
        from rerun.chunk import RrdReader
        if self.proc.poll() is None:
            self.signal_group(signal.SIGINT)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.signal_group(signal.SIGKILL)
        with warnings.catch_warnings():  # a streamed .rrd has no footer; RrdReader warns about that
            warnings.simplefilter("ignore")
            return list(RrdReader(str(self.path)).stream())


@pytest.fixture()
def sink(tmp_path):
    s = Sink(tmp_path / "sink.rrd")
    yield s
    s.signal_group(signal.SIGKILL)  # whatever of the group is still running (a test may have stopped the wrapper)
    if s.proc.poll() is None:
        s.proc.wait(5)


@pytest.fixture(scope="module")
def small_video(tmp_path_factory):
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    d = tmp_path_factory.mktemp("live") / "sim"
    simulate(SimulationConfig(n_nodes=8, n_frames=150, seed=2)).write(d, video=True)
    return d


def _entities(chunks) -> set[str]:
    return {c.entity_path for c in chunks if not c.entity_path.startswith("/__")}


def test_track_streams_video_and_every_frames_points(sink, small_video, tmp_path):
    d = small_video
    out = tmp_path / "tracks.csv"
    assert main(["track", str(d / "video.mp4"), str(d / "annotations.json"), "--graph", str(d / "graph.json"),
                 "--out", str(out), "--max-frames", "40", "--no-progress", "--connect", sink.address]) == 0
    chunks = sink.stop()
    assert {"/image/video", "/image/tracks/raw"} <= _entities(chunks)
    rows = [c.to_record_batch() for c in chunks if c.entity_path == "/image/tracks/raw"]
    frames = np.concatenate([rb.column("frame").to_numpy() for rb in rows])
    assert sorted(frames.tolist()) == list(range(40))  # one row per tracked frame, streamed as it was tracked
    pos = {int(f): np.asarray(p.as_py() if hasattr(p, "as_py") else p, dtype=float)
           for rb in rows for f, p in zip(rb.column("frame").to_numpy(), rb.column("Points2D:positions").to_pylist())}
    tr = pd.read_csv(out)
    f10 = tr[(tr.frame == 10) & (tr.visible == 1)].sort_values("point_id")
    np.testing.assert_allclose(np.asarray(pos[10]).reshape(-1, 2), f10[["x", "y"]].to_numpy(), atol=1e-3)


@pytest.mark.slow
def test_run_streams_the_same_entities_as_the_saved_recording(sink, small_video, tmp_path):
    from rerun.chunk import RrdReader
    d = small_video
    rrd = tmp_path / "saved.rrd"
    assert main(["run", str(d / "video.mp4"), str(d / "annotations.json"), str(d / "graph.json"),
                 "--out", str(tmp_path / "run"), "--rerun", str(rrd), "--bootstrap", "5", "--seed", "0",
                 "--effects", "offset", "--no-figures", "--no-progress", "--connect", sink.address]) == 0
    live = sink.stop()
    saved = _entities(RrdReader(str(rrd)).stream())
    got = _entities(live)
    assert saved <= got, f"not streamed live: {sorted(saved - got)[:5]}"
    assert {"/image/video", "/image/tracks/raw", "/summary/kappa", "/diagnosis/report"} <= got
    order = [c.entity_path for c in live]
    # tracks arrive while tracking runs, before the analysis; the diagnosis after the analysis
    assert order.index("/image/tracks/raw") < order.index("/summary/kappa") < order.index("/diagnosis/report")


def test_connect_to_nothing_is_one_line_before_any_work(small_video, tmp_path, capsys):
    d = small_video
    port = _free_port()  # nothing listens there
    rc = main(["track", str(d / "video.mp4"), str(d / "annotations.json"), "--out", str(tmp_path / "t.csv"),
               "--no-progress", "--connect", f"127.0.0.1:{port}"])
    err = capsys.readouterr().err
    assert rc == 2 and f"--connect: nothing accepts connections at 127.0.0.1:{port}" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "t.csv").exists()
    assert main(["track", str(d / "video.mp4"), str(d / "annotations.json"), "--out", str(tmp_path / "t.csv"),
                 "--connect", "not an address"]) == 2


def test_viewer_is_the_one_beside_this_python():
    import shlex

    from rce_gtsam.viewer import open_command, viewer_executable
    here = Path(sys.executable).parent / "rerun"
    if not here.is_file():
        pytest.skip("rerun-sdk's viewer is not installed beside this interpreter")
    assert viewer_executable() == str(here)
    assert shlex.split(open_command("out/x.rrd")) == [str(here), "out/x.rrd"]


def test_spawn_without_a_display_is_one_line_before_any_work(small_video, tmp_path, capsys, monkeypatch):
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is for Linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    d = small_video
    rc = main(["track", str(d / "video.mp4"), str(d / "annotations.json"), "--out", str(tmp_path / "t.csv"),
               "--no-progress", "--spawn"])
    err = capsys.readouterr().err
    assert rc == 2 and "--spawn: no display to open a Rerun viewer on" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "t.csv").exists()
