"""``rce simulate``'s 3-D options: ``--effect out_of_plane``'s ``--oop-share``, ``--tilt-deg`` and ``--depth``."""

from __future__ import annotations

import argparse
import math

from ..errors import InputError


def scene_from_args(args: argparse.Namespace, effects: tuple[str, ...], strengths: dict | None):
    """(strengths with ``--oop-share`` folded in, a :class:`~rce_gtsam.sim.three_d.Scene3D` or None).

    The scene is 3-D when the branch swings out of plane, when ``--tilt-deg`` is given or when ``--depth`` asks for
    depth; otherwise None (the planar simulator, unchanged). Raises :class:`InputError` naming the option on a
    bad value, before any work.
    """
    from ..sim.three_d import Scene3D
    strengths = dict(strengths or {})
    oop = "out_of_plane" in effects
    if args.oop_share is not None:
        if not oop:
            raise InputError("--oop-share", "is set but the branch does not swing out of plane; add --effect out_of_plane")
        if "out_of_plane" in strengths:
            raise InputError("--oop-share", "and --strength out_of_plane=... both set the share; give one")
        strengths["out_of_plane"] = args.oop_share
    share = strengths.get("out_of_plane")
    if share is not None and not (math.isfinite(share) and 0 <= share <= 2):
        option = "--oop-share" if args.oop_share is not None else "--strength"
        raise InputError(option, f"the out-of-plane share must be a number in [0, 2], got {share:g}")
    if args.tilt_deg is not None and not (math.isfinite(args.tilt_deg) and abs(args.tilt_deg) <= 75):
        raise InputError("--tilt-deg", f"must be a number of degrees in [-75, 75] (beyond, the branch is seen edge-on), "
                                       f"got {args.tilt_deg:g}")
    if args.depth:
        from ..track.sources import import_pyrealsense2
        import_pyrealsense2()   # a missing pyrealsense2 / libusb is named before anything is rendered
    scene = Scene3D(tilt_deg=args.tilt_deg) if (oop or args.tilt_deg is not None or args.depth) else None
    return strengths or None, scene
