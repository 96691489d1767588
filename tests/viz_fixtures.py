"""A small analysis shared by the viz tests: a short simulated branch (7 nodes x 150 frames)."""

from __future__ import annotations

import numpy as np


def small_analysis(seed: int = 1, n_nodes: int = 7, n_frames: int = 150, n_boot: int = 50):
    """(Simulation, AnalysisResult) of a short simulated chain; about 0.2 s."""
    import rce_gtsam
    from rce_gtsam.sim.simulate import SimulationConfig, simulate
    sim = simulate(SimulationConfig(n_nodes=n_nodes, n_frames=n_frames, seed=seed))
    return sim, rce_gtsam.analyze(sim.tracks, sim.graph, n_boot=n_boot)


def write_mp4v_video(path, n_frames: int, size=(160, 120)) -> None:
    """An MPEG-4 Part 2 ('mp4v', what OpenCV writes by default) video: Rerun cannot play it as is."""
    import av
    w, h = size
    with av.open(str(path), "w") as c:
        s = c.add_stream("mpeg4", rate=30)
        s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        for f in range(n_frames):
            img = np.full((h, w, 3), 60, np.uint8)
            x = f % (w - 20)
            img[h // 3:h // 3 + 20, x:x + 20] = 255
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
