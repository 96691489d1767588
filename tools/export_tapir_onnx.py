#!/usr/bin/env python
"""Export TAPIR / BootsTAPIR (online, causal) to the two ONNX files `rce track --model DIR` reads.

NOT RUN IN CI. Needs: torch, the official `tapnet` package (google-deepmind/tapnet, PyTorch model in
`tapnet/torch/tapir_model.py`; it also imports `einshape` and `dm-tree`) and the checkpoint
`causal_bootstapir_checkpoint.pt` (Apache-2.0, from
https://storage.googleapis.com/dm-tapnet/bootstap/causal_bootstapir_checkpoint.pt -- download it yourself;
this script never downloads anything). onnxruntime, if installed, is used to check the written files.

Writes OUT_DIR/tapir.onnx (predictor, one call per frame) and OUT_DIR/tapir_pointencoder.onnx with the
layout documented in rce_gtsam/track/tapir.py (the de-facto layout of ibaiGorordo/Tapir-Pytorch-Inference):
  encoder   in  query_points [1,N,2] (y,x)/R, feature_grid [1,R/8,R/8,256], hires_feats_grid [1,R/4,R/4,128]
            out query_feats [1,N,256], hires_query_feats [1,N,128]
  predictor in  input_frame [1,3,R,R] in [-1,1], query_feats, hires_query_feats,
                causal_state [iters=4,12,N,2,2560]
            out tracks [1,N,2] (x,y) R-pixels, visibles [1,N] bool, new_causal_state, feature_grid,
                hires_feats_grid, and (unless --no-logits) occlusion [1,N], expected_dist [1,N] logits,
                which rce turns into visibility and per-observation sigma_px.

The model is built at initial_resolution = (R, R) (as Tapir-Pytorch-Inference does), so there is exactly one
refinement level at R: one feature grid pair, iters = num_pips_iter = 4. For R = 256 this is the official
default. The predictor calls the official TAPIR.get_feature_grids / estimate_trajectories unchanged. The
encoder samples the query features with a 4-D grid_sample, which for one frame is exactly the official
get_query_features (whose 5-D grid_sample torch.onnx.export cannot convert below opset 20, tapnet issue #79);
the script checks the two agree before exporting.

Checked on 2026-11-22 against tapnet's torch code (google-deepmind/tapnet 6af490dd) with random weights,
torch 2.14.1: ONNX vs torch max difference 4.6e-5 px on tracks (state 1.7e-5); through rce's
TapirOnnxTracker (12 points in groups of 8, 6 frames) 7.6e-5 px and 100 % visibility agreement with the
official online path; --dynamic and --resolution 128 --no-logits exported too. Not checked: the real
checkpoint (not downloadable here).

CPU cost of the real model (2-core machine, R=256, N=64): ~3 s/frame; use a GPU machine or few points.

Usage:
  python tools/export_tapir_onnx.py CHECKPOINT.pt OUT_DIR [--resolution 256] [--num-points 64 | --dynamic]
                                     [--no-logits] [--opset 17]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NUM_BLOCKS = 12          # TAPIR mixer blocks: TAPIR(num_mixer_blocks=12) in tapnet/torch/tapir_model.py
STATE_CHANNELS = 2560    # 512 (block_i_causal_1) + 2048 (block_i_causal_2): TAPIR.construct_initial_causal_state
CHUNK_ALL = 1 << 30      # query_chunk_size larger than any N: one chunk, so a dynamic N is not cut at export N


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint", type=Path, help="causal_bootstapir_checkpoint.pt (PyTorch)")
    p.add_argument("out_dir", type=Path)
    p.add_argument("--resolution", type=int, default=256, help="model input R (R x R); multiple of 8")
    p.add_argument("--num-points", type=int, default=64, help="points per call N (fixed)")
    p.add_argument("--dynamic", action="store_true", help="make N a dynamic axis instead")
    p.add_argument("--no-logits", action="store_true", help="omit the occlusion/expected_dist outputs")
    p.add_argument("--opset", type=int, default=17)
    return p.parse_args(argv)


def sample_query_features(grid, query_points):
    """grid [1,h,w,C], query_points [1,N,2] (y,x) in [0,1] -> [1,N,C].

    Same numbers as tapnet/torch/utils.py map_coordinates_3d (bilinear, padding_mode='border',
    align_corners=False) as called by TAPIR.get_query_features with one frame: there the (t,y,x) point is
    scaled to grid cells ('tyx' convert_grid_coordinates), t gets +0.5 and everything is mapped to
    2 * p / size - 1, so t lands on the centre of the single frame and (y,x) on 2 * (y,x)/R - 1.
    """
    import torch
    import torch.nn.functional as F

    g = torch.flip(query_points, dims=(-1,)) * 2.0 - 1.0           # (x,y) in [-1,1], grid_sample order
    out = F.grid_sample(grid.permute(0, 3, 1, 2), g[:, :, None, :], mode="bilinear",
                        padding_mode="border", align_corners=False)   # [1,C,N,1]
    return out[..., 0].permute(0, 2, 1)


def build_modules(checkpoint: Path, resolution: int, logits: bool):
    import torch
    from tapnet.torch import tapir_model

    r = resolution
    # tapnet/torch/tapir_model.py: TAPIR.__init__(..., num_pips_iter=4, pyramid_level=1, num_mixer_blocks=12,
    # initial_resolution=(256, 256), extra_convs=True, use_casual_conv=False) -- "casual" is upstream's spelling
    # (nets.PIPSMLPMixer spells it use_causal_conv); tapnet/pytorch_live_demo.py builds the online model as
    # TAPIR(pyramid_level=1, use_casual_conv=True) and loads the .pt with model.load_state_dict(torch.load(...)).
    model = tapir_model.TAPIR(pyramid_level=1, use_casual_conv=True, initial_resolution=(r, r))
    model.load_state_dict(torch.load(checkpoint, map_location="cpu"))  # the .pt is a plain state_dict
    model.eval()

    with torch.no_grad():
        probe = model.get_feature_grids(torch.zeros(1, 1, r, r, 3), is_training=False)
    # tapir_model.py estimate_trajectories: num_iters = num_pips_iter * (len(feature_grids.lowres) - 1), one
    # causal_context dict per iteration
    if len(probe.lowres) != 2:
        raise RuntimeError(f"expected one refinement level at {r}x{r}, got resolutions {probe.resolutions}")
    iters = model.num_pips_iter * (len(probe.lowres) - 1)
    c_low, c_high = probe.lowres[0].shape[-1], probe.hires[0].shape[-1]   # 256, 128 (model.lowres_dim/highres_dim)

    def state_to_context(state):
        # [iters, 12, N, 2, 2560] -> list over iterations of {block_i_causal_1: [1,N,2,512], ..._2: [1,N,2,2048]}
        # (key names and shapes: tapir_model.py construct_initial_causal_state, nets.py PIPsConvBlock.forward)
        ctx = []
        for it in range(state.shape[0]):
            d = {}
            for b in range(NUM_BLOCKS):
                d[f"block_{b}_causal_1"] = state[it, b, None, :, :, :512]
                d[f"block_{b}_causal_2"] = state[it, b, None, :, :, 512:]
            ctx.append(d)
        return ctx

    def context_to_state(ctx):
        return torch.stack([torch.stack([torch.cat([c[f"block_{b}_causal_1"][0], c[f"block_{b}_causal_2"][0]], -1)
                                         for b in range(NUM_BLOCKS)]) for c in ctx])

    class Predictor(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.model = model  # a registered submodule, so the tracer exports the weights as initialisers

        def forward(self, input_frame, query_feats, hires_query_feats, causal_state):
            video = input_frame.permute(0, 2, 3, 1)[:, None]  # [1,1,R,R,3], values in [-1,1] (live demo)
            grids = self.model.get_feature_grids(video, is_training=False)
            # QueryFeatures(lowres, hires, resolutions): one entry per entry of grids (initial + refinement);
            # both are at R x R here, so the encoder's features serve both (what get_query_features returns)
            n_res = len(grids.resolutions)
            qf = tapir_model.QueryFeatures(lowres=(query_feats,) * n_res, hires=(hires_query_feats,) * n_res,
                                           resolutions=grids.resolutions)
            # signature as in tapir_model.py; call pattern as in pytorch_live_demo.py online_model_predict
            # (query_chunk_size must be an int: it is the step of a range())
            out = self.model.estimate_trajectories(video.shape[-3:-1], is_training=False, feature_grids=grids,
                                                   query_features=qf, query_points_in_video=None,
                                                   query_chunk_size=CHUNK_ALL,
                                                   causal_context=state_to_context(causal_state),
                                                   get_causal_context=True)
            # outputs are lists over iterations; [-1] = final refinement (live demo). tracks [B,N,T,2] (x,y)
            # raster coords of video_size; occlusion / expected_dist [B,N,T] logits (higher = occluded / far)
            tracks = out["tracks"][-1][:, :, 0]
            occ = out["occlusion"][-1][:, :, 0]
            ed = out["expected_dist"][-1][:, :, 0]
            visibles = (1 - torch.sigmoid(occ)) * (1 - torch.sigmoid(ed)) > 0.5  # live demo postprocess_occlusions
            res = [tracks, visibles, context_to_state(out["causal_context"]),
                   grids.lowres[0][:, 0], grids.hires[0][:, 0]]
            return tuple(res + ([occ, ed] if logits else []))

    class Encoder(torch.nn.Module):
        def forward(self, query_points, feature_grid, hires_feats_grid):
            return (sample_query_features(feature_grid, query_points),
                    sample_query_features(hires_feats_grid, query_points))

    # check the 4-D encoder against the official get_query_features (query points (t,y,x) in video pixels)
    with torch.no_grad():
        gen = torch.Generator().manual_seed(0)
        fg = torch.randn(1, r // 8, r // 8, c_low, generator=gen)
        hg = torch.randn(1, r // 4, r // 4, c_high, generator=gen)
        yx = torch.rand(1, 16, 2, generator=gen) * 1.1 - 0.05
        grids = tapir_model.FeatureGrids(lowres=(fg[:, None],), hires=(hg[:, None],), resolutions=((r, r),))
        q = torch.cat([torch.zeros_like(yx[..., :1]), yx * r], -1)
        ref = model.get_query_features(torch.zeros(1, 1, r, r, 3), is_training=False, query_points=q,
                                       feature_grids=grids)
        mine = Encoder()(yx, fg, hg)
        err = max(float((mine[0] - ref.lowres[0]).abs().max()), float((mine[1] - ref.hires[0]).abs().max()))
    if err > 1e-4:
        raise RuntimeError(f"4-D query sampling disagrees with tapnet get_query_features (max |diff| {err:.2e})")

    return Predictor().eval(), Encoder().eval(), iters, (c_low, c_high)


def check_with_onnxruntime(out_dir: Path, predictor, encoder, r: int, n: int, iters: int, dims, logits: bool) -> None:
    """Run both ONNX files on a random frame and compare with torch (skipped without onnxruntime)."""
    try:
        import onnxruntime as ort
    except ImportError:
        print("onnxruntime not installed: skipped the ONNX-vs-torch check")
        return
    import numpy as np
    import torch

    gen = torch.Generator().manual_seed(1)
    frame = torch.rand(1, 3, r, r, generator=gen) * 2 - 1
    yx = torch.rand(1, n, 2, generator=gen)
    state = torch.zeros(iters, NUM_BLOCKS, n, 2, STATE_CHANNELS)
    enc = ort.InferenceSession(str(out_dir / "tapir_pointencoder.onnx"), providers=["CPUExecutionProvider"])
    pred = ort.InferenceSession(str(out_dir / "tapir.onnx"), providers=["CPUExecutionProvider"])
    names = [o.name for o in pred.get_outputs()]
    with torch.no_grad():
        t0 = predictor(frame, torch.zeros(1, n, dims[0]), torch.zeros(1, n, dims[1]), state)
        tq = encoder(yx, t0[3], t0[4])
        t1 = predictor(frame, tq[0], tq[1], state)
    o0 = pred.run(None, {"input_frame": frame.numpy(), "query_feats": np.zeros((1, n, dims[0]), np.float32),
                         "hires_query_feats": np.zeros((1, n, dims[1]), np.float32), "causal_state": state.numpy()})
    oq = enc.run(None, {"query_points": yx.numpy(), "feature_grid": o0[3], "hires_feats_grid": o0[4]})
    o1 = pred.run(None, {"input_frame": frame.numpy(), "query_feats": oq[0], "hires_query_feats": oq[1],
                         "causal_state": state.numpy()})
    for name, a, b in zip(names, o1, t1):
        diff = float(np.abs(a.astype(np.float64) - b.numpy().astype(np.float64)).max())
        print(f"  {name:18s} {list(a.shape)!s:24s} max |onnx - torch| = {diff:.3g}")
    print(f"  query_feats max |onnx - torch| = {float(np.abs(oq[0] - tq[0].numpy()).max()):.3g}")


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        import torch
    except ImportError:
        print("this exporter needs torch and tapnet (pip install torch; pip install git+https://github.com/"
              "google-deepmind/tapnet)", file=sys.stderr)
        return 2
    if not args.checkpoint.is_file():
        print(f"{args.checkpoint}: checkpoint not found", file=sys.stderr)
        return 2
    r, n = args.resolution, args.num_points
    if r <= 0 or r % 8:
        print(f"--resolution must be a positive multiple of 8 (TAPIR.get_feature_grids), got {r}", file=sys.stderr)
        return 2
    logits = not args.no_logits
    predictor, encoder, iters, (c_low, c_high) = build_modules(args.checkpoint, r, logits)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    frame = torch.zeros(1, 3, r, r)
    qf, hqf = torch.zeros(1, n, c_low), torch.zeros(1, n, c_high)
    state = torch.zeros(iters, NUM_BLOCKS, n, 2, STATE_CHANNELS)
    out_names = ["tracks", "visibles", "new_causal_state", "feature_grid", "hires_feats_grid"]
    out_names += ["occlusion", "expected_dist"] if logits else []
    dyn = None
    if args.dynamic:
        dyn = {"query_feats": {1: "N"}, "hires_query_feats": {1: "N"}, "causal_state": {2: "N"},
               "tracks": {1: "N"}, "visibles": {1: "N"}, "new_causal_state": {2: "N"}}
        if logits:
            dyn.update({"occlusion": {1: "N"}, "expected_dist": {1: "N"}})
    with torch.no_grad():
        torch.onnx.export(predictor, (frame, qf, hqf, state), str(args.out_dir / "tapir.onnx"),
                          input_names=["input_frame", "query_feats", "hires_query_feats", "causal_state"],
                          output_names=out_names, opset_version=args.opset, dynamic_axes=dyn, dynamo=False)
        fg, hg = torch.zeros(1, r // 8, r // 8, c_low), torch.zeros(1, r // 4, r // 4, c_high)
        torch.onnx.export(encoder, (torch.zeros(1, n, 2), fg, hg), str(args.out_dir / "tapir_pointencoder.onnx"),
                          input_names=["query_points", "feature_grid", "hires_feats_grid"],
                          output_names=["query_feats", "hires_query_feats"], opset_version=args.opset,
                          dynamic_axes=({"query_points": {1: "N"}, "query_feats": {1: "N"},
                                         "hires_query_feats": {1: "N"}} if args.dynamic else None), dynamo=False)
    print(f"wrote {args.out_dir / 'tapir.onnx'} and {args.out_dir / 'tapir_pointencoder.onnx'}")
    check_with_onnxruntime(args.out_dir, predictor, encoder, r, n, iters, (c_low, c_high), logits)
    return 0


if __name__ == "__main__":
    sys.exit(main())
