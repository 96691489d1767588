"""TAPIR / BootsTAPIR through ONNX Runtime: the per-frame causal two-graph export.

Model layout (see ``tools/export_tapir_onnx.py`` and ecosystem-notes §1a), R = model resolution,
N = points per call, S = causal-state shape ``[iters, blocks, N, 2, C]``:

``tapir_pointencoder.onnx``
    in  ``query_points`` [1, N, 2] (y, x) normalised to [0, 1]; ``feature_grid`` [1, R/8, R/8, C1];
        ``hires_feats_grid`` [1, R/4, R/4, C2]
    out ``query_feats`` [1, N, C1]; ``hires_query_feats`` [1, N, C2]
``tapir.onnx`` (predictor, one call per frame)
    in  ``input_frame`` [1, 3, R, R] RGB in [-1, 1]; ``query_feats``; ``hires_query_feats``; ``causal_state`` S
    out ``tracks`` [1, N, 2] (x, y) in R x R pixels; ``visibles`` [1, N] bool; ``new_causal_state`` S;
        ``feature_grid``; ``hires_feats_grid``; optionally ``occlusion`` and ``expected_dist`` [1, N] logits.

Protocol (causal, streaming): on the query frame (frame 0, where the annotations are) run the predictor
with zero query features and zero state to get the feature grids, run the encoder on the normalised
query points, then call the predictor once per frame (frame 0 included) feeding ``new_causal_state``
back as ``causal_state``. Memory is constant in video length: only the state (S floats per point
group) and the (P, F) outputs are kept. Points beyond the model's N are processed in groups of N,
each with its own state ("chunking"); a fixed-N model with fewer points is padded with copies of the
first point whose outputs are discarded.

Coordinates: TAPIR puts (0, 0) at the top-left *corner* of the top-left pixel (pixel centres at
+0.5); we use pixel centres at integers. So a point (x, y) in the original W x H image is
((x + 0.5) / W, (y + 0.5) / H) normalised and the model's (x_R, y_R) maps back to
(x_R * W / R - 0.5, y_R * H / R - 0.5).

Uncertainty: if the predictor exposes the ``occlusion`` and ``expected_dist`` logits,
``p_visible = (1 - sigmoid(occlusion)) * (1 - sigmoid(expected_dist))`` and visible = p > 0.5 (the
official TAPIR rule). ``sigmoid(expected_dist)`` is TAPIR's estimate of u = P(error > d) with
d = ``expected_dist_thresh_px`` = 6 px at 256 x 256 (the threshold of TAPIR's training loss). For an
isotropic 2-D Gaussian error with per-axis sigma s, P(|e| > d) = exp(-d^2 / (2 s^2)), hence
s = d / sqrt(-2 ln u), in model pixels (d scales with R / 256), converted to original pixels with
max(W, H) / R (conservative for a non-square image). Without the logits, ``sigma_px`` is
``default_sigma_model_px`` model pixels converted the same way.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import InputError, MissingDependencyError
from .result import TrackResult
from .sources import FrameSource

PREDICTOR_FILE = "tapir.onnx"
ENCODER_FILE = "tapir_pointencoder.onnx"

PREDICTOR_INPUTS = {"input_frame": 4, "query_feats": 3, "hires_query_feats": 3, "causal_state": 5}
PREDICTOR_OUTPUTS = {"tracks": 3, "visibles": 2, "new_causal_state": 5, "feature_grid": 4, "hires_feats_grid": 4}
OPTIONAL_OUTPUTS = {"occlusion": 2, "expected_dist": 2}
ENCODER_INPUTS = {"query_points": 3, "feature_grid": 4, "hires_feats_grid": 4}
ENCODER_OUTPUTS = {"query_feats": 3, "hires_query_feats": 3}


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def resolve_model_files(model: str | Path) -> tuple[Path, Path]:
    """``model`` is a directory holding both files, or the predictor ``.onnx`` with the encoder beside it."""
    m = Path(model)
    if m.is_dir():
        pred, enc = m / PREDICTOR_FILE, m / ENCODER_FILE
    elif m.is_file():
        pred, enc = m, m.parent / ENCODER_FILE
    else:
        raise InputError(m, "TAPIR model not found; give a directory with tapir.onnx and tapir_pointencoder.onnx "
                            "(tools/export_tapir_onnx.py writes them)")
    for p in (pred, enc):
        if not p.is_file():
            raise InputError(p, f"missing; a TAPIR model needs both {PREDICTOR_FILE} and {ENCODER_FILE} in one folder")
    return pred, enc


def _check_signature(path: Path, sess, want_in: dict, want_out: dict, optional_out: dict | None = None) -> None:
    found_in = {i.name: i.shape for i in sess.get_inputs()}
    found_out = {o.name: o.shape for o in sess.get_outputs()}
    problems = []
    for kind, want, found in (("input", want_in, found_in), ("output", want_out, found_out)):
        for name, rank in want.items():
            if name not in found:
                problems.append(f"{kind} '{name}' (rank {rank}) is missing")
            elif len(found[name]) != rank:
                problems.append(f"{kind} '{name}' has rank {len(found[name])}, expected {rank}")
    for name, rank in (optional_out or {}).items():
        if name in found_out and len(found_out[name]) != rank:
            problems.append(f"output '{name}' has rank {len(found_out[name])}, expected {rank}")
    if problems:
        exp = (f"inputs {sorted(want_in)}; outputs {sorted(want_out)}"
               + (f" (+ optional {sorted(optional_out)})" if optional_out else ""))
        got = f"inputs {found_in}; outputs {found_out}"
        raise InputError(path, "not a TAPIR causal export: " + "; ".join(problems)
                               + f". Expected {exp}. Found {got}")


class TapirOnnxTracker:
    """Track points with a TAPIR ONNX export (see module docstring for layout and conventions).

    model: folder with ``tapir.onnx`` + ``tapir_pointencoder.onnx``, or the path of ``tapir.onnx``.
    expected_dist_thresh_px: TAPIR's expected-distance threshold at 256 x 256 (pixels), scaled by R/256.
    default_sigma_model_px: sigma (model pixels) used when the model has no logit outputs.
    num_threads: ONNX Runtime intra-op threads (0 = ORT default).
    """

    def __init__(self, model: str | Path, expected_dist_thresh_px: float = 6.0,
                 default_sigma_model_px: float = 1.0, num_threads: int = 0):
        try:
            import onnxruntime as ort
        except ImportError:
            raise MissingDependencyError("TAPIR tracking needs onnxruntime: pip install onnxruntime") from None
        self.predictor_path, self.encoder_path = resolve_model_files(model)
        opts = ort.SessionOptions()
        opts.log_severity_level = 3  # errors only; ORT's graph-optimiser notices are not for users
        if num_threads:
            opts.intra_op_num_threads = int(num_threads)
        sessions = []
        for p in (self.predictor_path, self.encoder_path):
            try:
                sessions.append(ort.InferenceSession(str(p), sess_options=opts, providers=["CPUExecutionProvider"]))
            except Exception as exc:  # onnxruntime raises its own exception types
                raise InputError(p, f"ONNX Runtime cannot load this model: {exc}") from None
        self.predictor, self.encoder = sessions
        _check_signature(self.predictor_path, self.predictor, PREDICTOR_INPUTS, PREDICTOR_OUTPUTS, OPTIONAL_OUTPUTS)
        _check_signature(self.encoder_path, self.encoder, ENCODER_INPUTS, ENCODER_OUTPUTS)
        ins = {i.name: i for i in self.predictor.get_inputs()}
        frame_shape = ins["input_frame"].shape
        r1, r2 = frame_shape[2], frame_shape[3]
        if not (isinstance(r1, int) and r1 == r2 and frame_shape[1] == 3):
            raise InputError(self.predictor_path, f"'input_frame' must be [1, 3, R, R] with a fixed R, got {frame_shape}")
        self.resolution = int(r1)
        self.state_shape = list(ins["causal_state"].shape)
        n = ins["query_feats"].shape[1]
        self.num_points = int(n) if isinstance(n, int) else None  # None = dynamic
        for name in ("causal_state",):
            dims = ins[name].shape
            if not all(isinstance(d, int) for i, d in enumerate(dims) if i != 2):
                raise InputError(self.predictor_path, f"'{name}' must have fixed dims except axis 2 (points), got {dims}")
        self.query_dims = (ins["query_feats"].shape[2], ins["hires_query_feats"].shape[2])
        outs = {o.name for o in self.predictor.get_outputs()}
        self.has_logits = {"occlusion", "expected_dist"} <= outs
        self.expected_dist_thresh_px = float(expected_dist_thresh_px)
        self.default_sigma_model_px = float(default_sigma_model_px)
        self._out_names = ["tracks", "visibles", "new_causal_state"] + (["occlusion", "expected_dist"] if self.has_logits else [])
        self.network_time_s = 0.0

    # -- helpers --------------------------------------------------------------------------------
    def _run(self, sess, names, feeds):
        t = time.perf_counter()
        out = sess.run(names, feeds)
        self.network_time_s += time.perf_counter() - t
        return out

    def preprocess(self, image: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 RGB -> [1, 3, R, R] float32 in [-1, 1]."""
        import cv2

        r = self.resolution
        h, w = image.shape[:2]
        interp = cv2.INTER_AREA if (w > r or h > r) else cv2.INTER_LINEAR
        small = cv2.resize(image, (r, r), interpolation=interp)
        return (small.astype(np.float32).transpose(2, 0, 1)[None] * (2.0 / 255.0) - 1.0).astype(np.float32)

    def _groups(self, n_points: int) -> list[np.ndarray]:
        """Index groups of at most N points (padded to N with point 0 for a fixed-N model)."""
        size = self.num_points or n_points
        groups = []
        for start in range(0, n_points, size):
            idx = np.arange(start, min(start + size, n_points))
            if self.num_points and idx.size < size:
                idx = np.concatenate([idx, np.full(size - idx.size, idx[0])])
            groups.append(idx)
        return groups

    def _zeros_state(self, n: int) -> np.ndarray:
        shape = [d if i != 2 else n for i, d in enumerate(self.state_shape)]
        return np.zeros(shape, np.float32)

    # -- main -----------------------------------------------------------------------------------
    def track(self, source: FrameSource, query_points, graph=None, max_frames: int | None = None,
              progress: Callable[[int], object] | None = None,
              on_frame: Callable[[int, np.ndarray, np.ndarray], object] | None = None) -> TrackResult:
        """Track ``query_points`` (P, 2) original pixels given on the first frame of ``source``.

        ``graph`` is accepted for signature compatibility and not used (TAPIR tracks points independently).
        ``progress(1)`` is called after every frame (``tqdm.update`` fits), and
        ``on_frame(index, xy (P, 2) px, visible (P,))`` with that frame's result (live viewers).
        """
        q = np.asarray(query_points, dtype=float)
        if q.ndim != 2 or q.shape[1] != 2 or len(q) == 0:
            raise InputError("query points", f"expected a (P, 2) array, got {q.shape}")
        w, h = source.size
        r = self.resolution
        sx, sy = w / r, h / r
        scale = max(sx, sy)
        thresh = self.expected_dist_thresh_px * r / 256.0
        groups = self._groups(len(q))
        xs, vis, sig = [], [], []
        states, feats = None, None
        t0 = time.perf_counter()
        self.network_time_s = 0.0
        n_done = 0
        for frame in source:
            if max_frames is not None and n_done >= max_frames:
                break
            x = self.preprocess(frame.image)
            if feats is None:  # query frame: feature grids -> encoder
                n0 = self.num_points or len(groups[0])
                fg, hg = self._run(self.predictor, ["feature_grid", "hires_feats_grid"], {
                    "input_frame": x,
                    "query_feats": np.zeros((1, n0, self.query_dims[0]), np.float32),
                    "hires_query_feats": np.zeros((1, n0, self.query_dims[1]), np.float32),
                    "causal_state": self._zeros_state(n0)})
                feats = []
                for idx in groups:
                    qn = np.stack([(q[idx, 1] + 0.5) / h, (q[idx, 0] + 0.5) / w], axis=1)[None].astype(np.float32)
                    feats.append(self._run(self.encoder, ["query_feats", "hires_query_feats"],
                                           {"query_points": qn, "feature_grid": fg, "hires_feats_grid": hg}))
                states = [self._zeros_state(len(idx)) for idx in groups]
            fx = np.empty((len(q), 2))
            fv = np.empty(len(q), bool)
            fs = np.empty(len(q))
            for g, idx in enumerate(groups):
                outs = self._run(self.predictor, self._out_names, {
                    "input_frame": x, "query_feats": feats[g][0], "hires_query_feats": feats[g][1],
                    "causal_state": states[g]})
                tracks, visibles, states[g] = outs[0], outs[1], outs[2]
                n_real = min(len(idx), len(q) - g * len(groups[0]))
                sel = idx[:n_real]
                fx[sel, 0] = tracks[0, :n_real, 0] * sx - 0.5
                fx[sel, 1] = tracks[0, :n_real, 1] * sy - 0.5
                if self.has_logits:
                    occ, ed = outs[3][0, :n_real].astype(float), outs[4][0, :n_real].astype(float)
                    fv[sel] = (1 - _sigmoid(occ)) * (1 - _sigmoid(ed)) > 0.5
                    u = np.clip(_sigmoid(ed), 1e-6, 1 - 1e-6)
                    fs[sel] = thresh / np.sqrt(-2.0 * np.log(u)) * scale
                else:
                    fv[sel] = np.asarray(visibles[0, :n_real]).astype(bool)
                    fs[sel] = self.default_sigma_model_px * scale
            if not np.isfinite(fx).all():
                raise InputError(self.predictor_path, f"the model returned non-finite tracks at frame {frame.index}")
            xs.append(fx)
            vis.append(fv)
            sig.append(fs)
            n_done += 1
            if progress is not None:
                progress(1)
            if on_frame is not None:
                on_frame(n_done - 1, fx.copy(), fv.copy())
        if n_done == 0:
            raise InputError(getattr(source, "path", "<video>"), "the video has no frames")
        total = time.perf_counter() - t0
        info = {"tracker": "tapir-onnx", "model": str(self.predictor_path), "resolution": r,
                "frames": n_done, "point_groups": len(groups), "time_total_s": total,
                "time_network_s": self.network_time_s,
                "overhead_ms_per_frame": 1000.0 * (total - self.network_time_s) / n_done}
        return TrackResult(point_ids=np.arange(len(q)), xy=np.stack(xs, axis=1), visible=np.stack(vis, axis=1),
                           sigma_px=np.maximum(np.stack(sig, axis=1), 1e-3), fps=source.fps, info=info)
