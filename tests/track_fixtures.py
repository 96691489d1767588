"""Test fixtures for the tracking code: synthetic videos, a fake TAPIR ONNX pair, RealSense recordings, a simulation
rendered to H.264 with its true positions by node id.

Imported by tests/test_track_*.py (not a conftest: the lead owns tests/conftest.py).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

# ---------------------------------------------------------------------------------------------
# Moving Gaussian blob (for the fake TAPIR model)


def blob_video(n_frames=12, size=(160, 120), sigma=(7.0, 5.0), seed=0):
    """Frames (F, H, W, 3) uint8 with one bright Gaussian blob on black, and its centre (F, 2) in pixels
    (pixel centres at integers). The path is a smooth loop well inside the frame."""
    w, h = size
    t = np.arange(n_frames)
    centres = np.column_stack([w * 0.5 + w * 0.22 * np.cos(2 * np.pi * t / 9 + 0.3),
                               h * 0.5 + h * 0.2 * np.sin(2 * np.pi * t / 7)])
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    frames = np.empty((n_frames, h, w, 3), np.uint8)
    for f, (cx, cy) in enumerate(centres):
        g = np.exp(-0.5 * (((xx - cx) / sigma[0]) ** 2 + ((yy - cy) / sigma[1]) ** 2))
        frames[f] = np.round(255 * g)[..., None].astype(np.uint8)
    return frames, centres


# ---------------------------------------------------------------------------------------------
# Fake TAPIR export built with onnx.helper (same I/O names, ranks and layout as the real export)


def build_fake_tapir(out_dir: Path, resolution=64, n_points: int | str = "N", c1=8, c2=8,
                     state=(1, 2, 8), beta=8.0, with_logits=False, expected_dist_logit=-2.0,
                     rename: dict | None = None) -> Path:
    """Write ``tapir.onnx`` and ``tapir_pointencoder.onnx`` to ``out_dir``.

    The predictor's ``tracks`` = softmax(beta * grey)-weighted centroid of the frame (x, y in R x R
    pixels, pixel centres at +0.5 as TAPIR) blended with the previous frame's centroid carried in
    ``causal_state`` (0.5 * (c_f + c_{f-1}) once the state holds one), plus each point's query offset
    from the blob at the query frame (carried in ``query_feats[..., :2]``). So a correct runner sees
    the points move with the blob; one that does not feed the state back, swaps x/y or mis-normalises
    does not. ``visibles`` = brightest grey > 0 (a black frame = all occluded).
    ``state`` = (iters, blocks, channels) of ``causal_state`` [iters, blocks, N, 2, channels].
    ``rename`` maps standard tensor names to wrong ones (for signature-error tests).
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    rename = rename or {}
    nm = lambda s: rename.get(s, s)  # noqa: E731
    r = resolution
    iters, blocks, ch = state
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    n = n_points

    def const(name, arr, dtype=np.float32):
        return numpy_helper.from_array(np.asarray(arr, dtype=dtype), name)

    cols, rows = np.meshgrid(np.arange(r) + 0.5, np.arange(r) + 0.5)
    grid_xy = np.stack([cols.ravel(), rows.ravel()], axis=1)  # [R*R, 2]
    w_q = np.zeros((c1, 2)); w_q[0, 0] = w_q[1, 1] = 1
    w_e1 = np.zeros((2, c1)); w_e1[0, 0] = w_e1[1, 1] = 1
    w_e2 = np.zeros((2, c2)); w_e2[0, 0] = w_e2[1, 1] = 1
    inits = [
        const("flat_shape", [1, r * r], np.int64), const("beta", beta), const("grid_xy", grid_xy),
        const("w_q", w_q), const("half", 0.5), const("zero", 0.0), const("one11", [[1.0]]),
        const("s_start", [0], np.int64), const("s_end3", [3], np.int64), const("ax1", [1], np.int64),
        const("s_start1", [1], np.int64), const("s_end1", [1], np.int64), const("neg1", [1, -1], np.int64),
        const("zeros_state", np.zeros((1, ch - 3))), const("vec_shape", [ch], np.int64),
        const("zeros_c1", np.zeros((1, c1 - 2))), const("zeros_c2", np.zeros((1, c2 - 2))),
        const("fg_shape", [1, r // 8, r // 8, c1], np.int64), const("hg_shape", [1, r // 4, r // 4, c2], np.int64),
        const("ax2", [2], np.int64),
    ] + ([const("neg10", -10.0), const("ed_logit", expected_dist_logit)] if with_logits else [])
    nodes = [
        helper.make_node("ReduceMean", [nm("input_frame")], ["grey"], axes=[1], keepdims=0),
        helper.make_node("Reshape", ["grey", "flat_shape"], ["flat"]),
        helper.make_node("Mul", ["flat", "beta"], ["scaled"]),
        helper.make_node("Softmax", ["scaled"], ["wts"], axis=1),
        helper.make_node("MatMul", ["wts", "grid_xy"], ["c"]),  # [1, 2] (x, y)
        helper.make_node("MatMul", [nm("query_feats"), "w_q"], ["offset"]),  # [1, N, 2]
        helper.make_node("Reshape", [nm("causal_state"), "neg1"], ["sflat"]),
        helper.make_node("Slice", ["sflat", "s_start", "s_end3", "ax1"], ["s3"]),
        helper.make_node("Slice", ["s3", "s_start", "s_end1", "ax1"], ["flag"]),
        helper.make_node("Slice", ["s3", "s_start1", "s_end3", "ax1"], ["prev"]),
        helper.make_node("Sub", ["prev", "c"], ["dprev"]),
        helper.make_node("Mul", ["dprev", "flag"], ["dflag"]),
        helper.make_node("Mul", ["dflag", "half"], ["dhalf"]),
        helper.make_node("Add", ["c", "dhalf"], ["c_out"]),
        helper.make_node("Unsqueeze", ["c_out", "ax1"], ["c_out3"]),
        helper.make_node("Add", ["c_out3", "offset"], [nm("tracks")]),
        helper.make_node("ReduceMax", ["flat"], ["peak"], axes=[1], keepdims=1),  # [1, 1]
        helper.make_node("ReduceSum", ["offset", "ax2"], ["osum"], keepdims=0),  # [1, N]
        helper.make_node("Mul", ["osum", "zero"], ["zeros_n"]),
        helper.make_node("Add", ["zeros_n", "peak"], ["peak_n"]),
        helper.make_node("Greater", ["peak_n", "zero"], [nm("visibles")]),
        helper.make_node("Concat", ["one11", "c", "zeros_state"], ["svec"], axis=1),
        helper.make_node("Reshape", ["svec", "vec_shape"], ["svec1"]),
        helper.make_node("Shape", [nm("causal_state")], ["sshape"]),
        helper.make_node("Expand", ["svec1", "sshape"], [nm("new_causal_state")]),
        helper.make_node("Concat", ["c", "zeros_c1"], ["fvec"], axis=1),
        helper.make_node("Expand", ["fvec", "fg_shape"], [nm("feature_grid")]),
        helper.make_node("Concat", ["c", "zeros_c2"], ["hvec"], axis=1),
        helper.make_node("Expand", ["hvec", "hg_shape"], [nm("hires_feats_grid")]),
    ]
    outputs = [
        helper.make_tensor_value_info(nm("tracks"), TensorProto.FLOAT, [1, n, 2]),
        helper.make_tensor_value_info(nm("visibles"), TensorProto.BOOL, [1, n]),
        helper.make_tensor_value_info(nm("new_causal_state"), TensorProto.FLOAT, [iters, blocks, n, 2, ch]),
        helper.make_tensor_value_info(nm("feature_grid"), TensorProto.FLOAT, [1, r // 8, r // 8, c1]),
        helper.make_tensor_value_info(nm("hires_feats_grid"), TensorProto.FLOAT, [1, r // 4, r // 4, c2]),
    ]
    if with_logits:
        nodes += [helper.make_node("Mul", ["peak_n", "neg10"], ["occlusion"]),
                  helper.make_node("Add", ["zeros_n", "ed_logit"], ["expected_dist"])]
        outputs += [helper.make_tensor_value_info("occlusion", TensorProto.FLOAT, [1, n]),
                    helper.make_tensor_value_info("expected_dist", TensorProto.FLOAT, [1, n])]
    inputs = [
        helper.make_tensor_value_info(nm("input_frame"), TensorProto.FLOAT, [1, 3, r, r]),
        helper.make_tensor_value_info(nm("query_feats"), TensorProto.FLOAT, [1, n, c1]),
        helper.make_tensor_value_info(nm("hires_query_feats"), TensorProto.FLOAT, [1, n, c2]),
        helper.make_tensor_value_info(nm("causal_state"), TensorProto.FLOAT, [iters, blocks, n, 2, ch]),
    ]
    pred = helper.make_graph(nodes, "fake_tapir", inputs, outputs, initializer=inits)
    onnx.save(helper.make_model(pred, opset_imports=[helper.make_opsetid("", 17)], ir_version=8), out_dir / "tapir.onnx")

    enc_inits = [const("perm_idx", [1, 0], np.int64), const("R", float(r)), const("neg1", [1, -1], np.int64),
                 const("s_start", [0], np.int64), const("s_end2", [2], np.int64), const("ax1", [1], np.int64),
                 const("w_e1", w_e1), const("w_e2", w_e2)]
    enc_nodes = [
        helper.make_node("Gather", [nm("query_points"), "perm_idx"], ["qxy_n"], axis=2),  # (y,x) -> (x,y)
        helper.make_node("Mul", ["qxy_n", "R"], ["qxy"]),
        helper.make_node("Reshape", [nm("feature_grid"), "neg1"], ["fflat"]),
        helper.make_node("Slice", ["fflat", "s_start", "s_end2", "ax1"], ["c0"]),
        helper.make_node("Unsqueeze", ["c0", "ax1"], ["c03"]),
        helper.make_node("Sub", ["qxy", "c03"], ["off"]),
        helper.make_node("MatMul", ["off", "w_e1"], [nm("query_feats")]),
        helper.make_node("MatMul", ["off", "w_e2"], [nm("hires_query_feats")]),
    ]
    enc = helper.make_graph(enc_nodes, "fake_encoder", [
        helper.make_tensor_value_info(nm("query_points"), TensorProto.FLOAT, [1, n, 2]),
        helper.make_tensor_value_info(nm("feature_grid"), TensorProto.FLOAT, [1, r // 8, r // 8, c1]),
        helper.make_tensor_value_info(nm("hires_feats_grid"), TensorProto.FLOAT, [1, r // 4, r // 4, c2]),
    ], [helper.make_tensor_value_info(nm("query_feats"), TensorProto.FLOAT, [1, n, c1]),
        helper.make_tensor_value_info(nm("hires_query_feats"), TensorProto.FLOAT, [1, n, c2])], initializer=enc_inits)
    onnx.save(helper.make_model(enc, opset_imports=[helper.make_opsetid("", 17)], ir_version=8), out_dir / "tapir_pointencoder.onnx")
    return out_dir


# ---------------------------------------------------------------------------------------------
# Synthetic textured swinging branch with a leaf occluder


@dataclass
class BranchVideo:
    frames: np.ndarray        # (F, H, W, 3) uint8 RGB
    true_xy: np.ndarray       # (N, F, 2) node centres, pixels
    occluded: np.ndarray      # (N, F) bool: the leaf covers the node's patch centre
    edges: list               # [[parent, child], ...] chain from node 0 (base)
    fps: float = 30.0


def _smooth_texture(rng, size, blur):
    t = rng.random((size, size)).astype(np.float32)
    t = cv2.GaussianBlur(t, (0, 0), blur)
    t = (t - t.min()) / (np.ptp(t) + 1e-9)
    return t


def branch_video(n_frames=121, size=(320, 240), n_nodes=8, segment_px=18.0, tip_amp_px=25.0,
                 period_frames=60, gust_amp_px=8.0, gust_period_frames=20, occluder=True, seed=0) -> BranchVideo:
    """A chain of textured node patches swinging about a base at the bottom of the frame.

    Each segment's angle from vertical is a sum of two sinusoids (a slow sway and a faster "gust"),
    growing toward the tip so the tip swings ~tip_amp_px + gust_amp_px. Periods divide n_frames - 1,
    so the last frame repeats the first pose (drift test). The branch patches are rotated with the
    local branch angle; a textured leaf crosses the distal nodes mid-clip when ``occluder``.
    """
    rng = np.random.default_rng(seed)
    w, h = size
    bg = (0.35 + 0.3 * _smooth_texture(rng, max(w, h), 6.0)[:h, :w])  # static, low-contrast background
    rad = int(round(0.6 * segment_px))
    tex_size = 2 * rad + 1
    textures = [0.15 + 0.85 * _smooth_texture(rng, tex_size, 1.2) for _ in range(n_nodes)]
    yy, xx = np.mgrid[0:tex_size, 0:tex_size]
    disk = (((xx - rad) ** 2 + (yy - rad) ** 2) <= rad ** 2).astype(np.float32)
    disk = cv2.GaussianBlur(disk, (0, 0), 0.7)
    leaf_tex = 0.2 + 0.5 * _smooth_texture(rng, 61, 2.0)
    base = np.array([w * 0.5, h - 25.0])
    t = np.arange(n_frames)
    total_len = segment_px * (n_nodes - 1)
    # angle per segment (radians), increasing with distance from the base
    amp_slow = tip_amp_px / total_len * 2 / (n_nodes - 1)
    amp_gust = gust_amp_px / total_len * 2 / (n_nodes - 1)
    true_xy = np.zeros((n_nodes, n_frames, 2))
    angles = np.zeros((n_nodes, n_frames))
    for f in range(n_frames):
        p = base.copy()
        ang = 0.0
        true_xy[0, f] = p
        for k in range(1, n_nodes):
            ang += (k / (n_nodes - 1)) * (amp_slow * math.sin(2 * math.pi * f / period_frames)
                                          + amp_gust * math.sin(2 * math.pi * f / gust_period_frames + 0.7))
            p = p + segment_px * np.array([math.sin(ang), -math.cos(ang)])
            true_xy[k, f] = p
            angles[k, f] = ang
        angles[0, f] = 0.0
    leaf_path = None
    occluded = np.zeros((n_nodes, n_frames), bool)
    frames = np.empty((n_frames, h, w, 3), np.uint8)
    tip0 = true_xy[-1, 0]
    for f in range(n_frames):
        img = bg.copy()
        for k in range(n_nodes):
            c = true_xy[k, f]
            m = cv2.getRotationMatrix2D((float(rad), float(rad)), -math.degrees(angles[k, f]), 1.0)
            m[:, 2] += c - rad
            warped = cv2.warpAffine(textures[k], m, (w, h), flags=cv2.INTER_LINEAR, borderValue=0)
            alpha = cv2.warpAffine(disk, m, (w, h), flags=cv2.INTER_LINEAR, borderValue=0)
            img = img * (1 - alpha) + warped * alpha
        if occluder:
            # a leaf sweeping horizontally across the distal third between 40 % and 60 % of the clip
            f0, f1 = 0.4 * n_frames, 0.6 * n_frames
            if f0 <= f <= f1:
                s = (f - f0) / (f1 - f0)
                lc = np.array([tip0[0] - 60 + 120 * s, tip0[1] + segment_px])
                mask = np.zeros((h, w), np.float32)
                cv2.ellipse(mask, (int(lc[0]), int(lc[1])), (22, 14), 20, 0, 360, 1.0, -1)
                mask = cv2.GaussianBlur(mask, (0, 0), 1.0)
                lt = cv2.resize(leaf_tex, (w, h))
                img = img * (1 - mask) + lt * mask
                leaf_path = lc
                for k in range(n_nodes):
                    x, y = true_xy[k, f]
                    if 0 <= int(round(y)) < h and 0 <= int(round(x)) < w:
                        occluded[k, f] = mask[int(round(y)), int(round(x))] > 0.05
        frames[f] = np.clip(np.round(img * 255), 0, 255).astype(np.uint8)[..., None].repeat(3, axis=2)
    del leaf_path
    return BranchVideo(frames=frames, true_xy=true_xy, occluded=occluded,
                       edges=[[k, k + 1] for k in range(n_nodes - 1)])


# ---------------------------------------------------------------------------------------------
# Writers


def write_mp4(frames: np.ndarray, path: Path, fps: float = 30.0) -> Path:
    """Write RGB frames as a near-lossless H.264 mp4 with PyAV (crf 0 keeps tracking tests honest)."""
    import av

    with av.open(str(path), "w") as out:
        st = out.add_stream("libx264", rate=int(fps))
        st.width, st.height = frames.shape[2], frames.shape[1]
        st.pix_fmt = "yuv444p"
        st.options = {"crf": "0", "preset": "ultrafast"}
        for im in frames:
            for pkt in st.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(im), format="rgb24")):
                out.mux(pkt)
        for pkt in st.encode():
            out.mux(pkt)
    return Path(path)


def record_realsense(path: Path, frames, fps: int = 30) -> Path:
    """Record RGB frames through pyrealsense2's software_device + recorder (.db3 with librealsense >= 2.58)."""
    import pyrealsense2 as rs

    h, w = frames[0].shape[:2]
    sd = rs.software_device()
    sensor = sd.add_sensor("RGB Camera")
    intr = rs.intrinsics()
    intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = w, h, 100.0, 100.0, w / 2, h / 2
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid, vs.width, vs.height, vs.fps, vs.bpp = rs.stream.color, 0, 0, w, h, fps, 3
    vs.fmt, vs.intrinsics = rs.format.rgb8, intr
    prof = sensor.add_video_stream(vs)
    rec = rs.recorder(str(path), sd)
    sensor.open(prof)
    sensor.start(rs.frame_queue(10))
    for i, im in enumerate(frames):
        fr = rs.software_video_frame()
        fr.pixels = np.ascontiguousarray(im)
        fr.bpp, fr.stride = 3, w * 3
        fr.timestamp = i * 1000.0 / fps
        fr.domain = rs.timestamp_domain.system_time
        fr.frame_number = i
        fr.profile = prof.as_video_stream_profile()
        sensor.on_video_frame(fr)
        time.sleep(0.01)  # the recorder writes on its own thread; do not outrun it
    time.sleep(0.2)
    sensor.stop()
    sensor.close()
    rec.pause()
    del rec
    return Path(path)


# ---------------------------------------------------------------------------------------------
# A simulation rendered to H.264, with its true positions by node id


def truth_by_node_id(sim, xy=None) -> np.ndarray:
    """(N, F, 2) px: ``xy`` (default the simulation's true positions, rows in ``sim.tracks.node_ids`` order) placed at
    each node's id, which is the row a tracker started from annotations writes it to."""
    xy = sim.true_xy if xy is None else xy
    truth = np.zeros_like(xy)
    truth[list(sim.tracks.node_ids)] = xy
    return truth


def rendered_simulation(tmp_path, config):
    """(simulation, video path, true positions by node id) of ``simulate(config)`` rendered to ``tmp_path/v.mp4``;
    skipped where the simulator or its renderer cannot be imported."""
    simulate = pytest.importorskip("rce_gtsam.sim.simulate")
    render = pytest.importorskip("rce_gtsam.sim.render")
    sim = simulate.simulate(config)
    video = render.render_video(sim, tmp_path / "v.mp4")
    return sim, video, truth_by_node_id(sim)
