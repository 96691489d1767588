#!/usr/bin/env python
"""Export TAPIR / BootsTAPIR (online, causal) to the two ONNX files `rce track --model DIR` reads.

NOT RUN IN CI. Needs: torch, the official `tapnet` package (google-deepmind/tapnet, PyTorch model in
`tapnet/torch/tapir_model.py`) and the checkpoint `causal_bootstapir_checkpoint.pt` (Apache-2.0, from
https://storage.googleapis.com/dm-tapnet/bootstap/causal_bootstapir_checkpoint.pt -- download it yourself;
this script never downloads anything).

Writes OUT_DIR/tapir.onnx (predictor, one call per frame) and OUT_DIR/tapir_pointencoder.onnx with the
layout documented in rce_gtsam/track/tapir.py (the de-facto layout of ibaiGorordo/Tapir-Pytorch-Inference):
  encoder   in  query_points [1,N,2] (y,x)/R, feature_grid [1,R/8,R/8,256], hires_feats_grid [1,R/4,R/4,128]
            out query_feats [1,N,256], hires_query_feats [1,N,128]
  predictor in  input_frame [1,3,R,R] in [-1,1], query_feats, hires_query_feats,
                causal_state [iters=4,12,N,2,2560]
            out tracks [1,N,2] (x,y) R-pixels, visibles [1,N] bool, new_causal_state, feature_grid,
                hires_feats_grid, and (with --logits, the default) occlusion [1,N], expected_dist [1,N] logits,
                which rce turns into visibility and per-observation sigma_px.

Caveat (tapnet issue #79): the official model samples features with a 5-D grid_sample that
torch.onnx.export cannot convert. If the export below fails with a GridSample error, export with
ibaiGorordo/Tapir-Pytorch-Inference (`onnx_export.py`, which rewrites the model per frame in 4-D) --
its files load in rce as they are (without the logit outputs: sigma_px is then a constant).

CPU cost of the real model (2-core machine, R=256, N=64): ~3 s/frame; use a GPU machine or few points.

Usage:
  python tools/export_tapir_onnx.py CHECKPOINT.pt OUT_DIR [--resolution 256] [--num-points 64 | --dynamic]
                                     [--no-logits] [--opset 17]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NUM_BLOCKS = 12          # TAPIR mixer blocks
STATE_CHANNELS = 2560    # 512 (causal_1) + 2048 (causal_2) per block


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


def build_modules(checkpoint: Path, logits: bool):
    import torch
    from tapnet.torch import tapir_model

    model = tapir_model.TAPIR(pyramid_level=1, use_casual_conv=True)
    model.load_state_dict(torch.load(checkpoint, map_location="cpu"))
    model.eval()
    iters = model.num_pips_iter

    def state_to_context(state):
        # [iters, 12, N, 2, 2560] -> list over iterations of {block_i_causal_1: [1,N,2,512], ..._2: [1,N,2,2048]}
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
        def forward(self, input_frame, query_feats, hires_query_feats, causal_state):
            video = input_frame.permute(0, 2, 3, 1)[:, None]  # [1,1,R,R,3]
            grids = model.get_feature_grids(video, is_training=False)
            qf = tapir_model.QueryFeatures(lowres=(query_feats,), hires=(hires_query_feats,))
            out = model.estimate_trajectories(video.shape[-3:-1], is_training=False, feature_grids=grids,
                                              query_features=qf, query_points_in_video=None,
                                              query_chunk_size=None, causal_context=state_to_context(causal_state),
                                              get_causal_context=True)
            tracks = out["tracks"][-1][:, :, 0]           # [1,N,2] (x,y)
            occ = out["occlusion"][-1][:, :, 0]           # logits [1,N]
            ed = out["expected_dist"][-1][:, :, 0]
            visibles = (1 - torch.sigmoid(occ)) * (1 - torch.sigmoid(ed)) > 0.5
            res = [tracks, visibles, context_to_state(out["causal_context"]),
                   grids.lowres[0][:, 0], grids.hires[0][:, 0]]
            return tuple(res + ([occ, ed] if logits else []))

    class Encoder(torch.nn.Module):
        def forward(self, query_points, feature_grid, hires_feats_grid):
            r = feature_grid.shape[1] * 8
            q = torch.cat([torch.zeros_like(query_points[..., :1]), query_points * r], -1)  # (t=0, y, x) pixels
            grids = tapir_model.FeatureGrids(lowres=(feature_grid[:, None],), hires=(hires_feats_grid[:, None],),
                                             highest=(feature_grid[:, None],), resolutions=((r, r),))
            qf = model.get_query_features(None, is_training=False, query_points=q, feature_grids=grids)
            return qf.lowres[0], qf.hires[0]

    return Predictor(), Encoder(), iters


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
    logits = not args.no_logits
    predictor, encoder, iters = build_modules(args.checkpoint, logits)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    frame = torch.zeros(1, 3, r, r)
    qf, hqf = torch.zeros(1, n, 256), torch.zeros(1, n, 128)
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
        fg, hg = torch.zeros(1, r // 8, r // 8, 256), torch.zeros(1, r // 4, r // 4, 128)
        torch.onnx.export(encoder, (torch.zeros(1, n, 2), fg, hg), str(args.out_dir / "tapir_pointencoder.onnx"),
                          input_names=["query_points", "feature_grid", "hires_feats_grid"],
                          output_names=["query_feats", "hires_query_feats"], opset_version=args.opset,
                          dynamic_axes=({"query_points": {1: "N"}, "query_feats": {1: "N"},
                                         "hires_query_feats": {1: "N"}} if args.dynamic else None), dynamo=False)
    print(f"wrote {args.out_dir / 'tapir.onnx'} and {args.out_dir / 'tapir_pointencoder.onnx'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
