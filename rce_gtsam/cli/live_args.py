"""``--spawn`` / ``--connect ADDR`` for commands that can stream into a Rerun viewer while they work."""

from __future__ import annotations

import argparse


def add_live_arguments(p: argparse.ArgumentParser) -> None:
    """Add the mutually exclusive ``--spawn`` and ``--connect ADDR`` options to ``p``."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--spawn", action="store_true",
                   help="open a Rerun viewer (this environment's `rerun`) and stream the video and tracks into it "
                        "while tracking runs, then the results as they finish")
    g.add_argument("--connect", default=None, metavar="ADDR",
                   help="stream live into a running Rerun viewer or gRPC server at ADDR (HOST:PORT or "
                        "rerun+http://HOST:PORT/proxy; a viewer started as `rerun` listens on 127.0.0.1:9876)")


def live_from_args(args: argparse.Namespace, title: str):
    """A :class:`~rce_gtsam.viz.live.LiveStream` when ``--spawn`` or ``--connect`` was given, else None.

    Call it before any slow work: a wrong address is an input error."""
    if not (args.spawn or args.connect):
        return None
    if args.spawn:
        from ..viewer import require_display
        require_display()
    from ..viz.live import LiveStream
    return LiveStream(title, spawn=args.spawn, connect=args.connect)
