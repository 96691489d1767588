"""``rce annotate VIDEO``: click the nodes in the browser; ``rce annotate --polyline ...`` for scripts."""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    a = sub.add_parser(
        "annotate", help="click the branch's nodes on a video's first frame in the browser (or place them along a polyline)",
        description="rce annotate VIDEO serves a page on 127.0.0.1 (printed, and opened in your browser when there "
                    "is one) showing the video's first frame: click the nodes root -> tip (each click snaps to the "
                    "stem's centre line), click an existing node to start a side branch from it, drag to move, "
                    "Ctrl+Z to undo, then Save: it writes DIR/annotations.json and DIR/graph.json and says which "
                    "`rce run` command comes next. For scripts: rce annotate --polyline x1,y1,... --nodes N "
                    "--out-annotations A.json --out-graph G.json places N nodes evenly along a polyline (a chain).")
    a.add_argument("video", type=Path, nargs="?", default=None,
                   help="video file (mp4/avi/...) or RealSense recording (.bag, .db3) to annotate in the browser")
    a.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="folder for annotations.json and graph.json (default: VIDEO's folder/<video name>_annotation; "
                        "an annotation already there is loaded so you can go on editing it)")
    a.add_argument("--port", type=int, default=0, help="local port of the page (default: a free one)")
    a.add_argument("--no-browser", action="store_true", help="only print the page's address")
    a.add_argument("--snap-radius", type=float, default=6.0, metavar="PX",
                   help="how far a click may move onto a stem's centre line (pixels; 0 = no snapping; default 6)")
    a.add_argument("--polyline", default=None, metavar="x1,y1,x2,y2,...",
                   help="script mode: polyline vertices in first-frame pixels, base first")
    a.add_argument("--nodes", type=int, default=None, metavar="N",
                   help="script mode: number of nodes along the polyline (>= 3: a bend needs three nodes)")
    a.add_argument("--out-annotations", type=Path, default=None, help="script mode: annotations JSON to write")
    a.add_argument("--out-graph", type=Path, default=None, help="script mode: graph JSON to write")
    # "--polyline -10,20,..." is a value, not an unknown option: let argparse take any argument made of
    # numbers and commas that starts with "-" as a value, so a negative vertex gets a clear message.
    a._negative_number_matcher = re.compile(r"^-\d*\.?\d+([,;]\s*-?\d*\.?\d+)*$")
    a.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError

    script = [n for n in ("polyline", "nodes", "out_annotations", "out_graph") if getattr(args, n) is not None]
    if script:
        missing = [n for n in ("polyline", "nodes", "out_annotations", "out_graph") if getattr(args, n) is None]
        if missing:
            raise InputError(f"--{missing[0].replace('_', '-')}", "the polyline mode needs --polyline, --nodes, "
                                                                  "--out-annotations and --out-graph")
        return _run_polyline(args)
    if args.video is None:
        raise InputError("rce annotate", "give a VIDEO to annotate in the browser, or --polyline ... --nodes N "
                                         "--out-annotations A.json --out-graph G.json")
    return _run_browser(args)


def _run_polyline(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from ..track import parse_polyline, place_nodes_along_polyline, write_annotation_files
    from ..validate import check_distinct_outputs, check_output_file

    check_output_file(args.out_annotations, "--out-annotations")
    check_output_file(args.out_graph, "--out-graph")
    check_distinct_outputs(("--out-annotations", args.out_annotations), ("--out-graph", args.out_graph))
    if args.nodes < 3:
        raise InputError("--nodes", f"must be >= 3 (a bend needs a node with a parent and a child), got {args.nodes}")
    poly = parse_polyline(args.polyline)
    neg = [i for i, (x, y) in enumerate(poly) if x < -0.5 or y < -0.5]
    if neg:
        x, y = poly[neg[0]]
        raise InputError("--polyline", f"vertex {neg[0]} (x={x:g}, y={y:g}) is outside the image: pixel "
                                       "coordinates start at 0 in the top-left corner")
    size = None
    if args.video is not None:
        from ..track import open_video
        with open_video(args.video) as src:
            size = src.size
        w, h = size
        out = [i for i, (x, y) in enumerate(poly) if x > w - 0.5 or y > h - 0.5]
        if out:
            x, y = poly[out[0]]
            raise InputError("--polyline", f"vertex {out[0]} (x={x:g}, y={y:g}) is outside the {w}x{h} frame of "
                                           f"{args.video}")
    points, graph = place_nodes_along_polyline(poly, args.nodes)
    write_annotation_files(points, graph, args.out_annotations, args.out_graph)
    print(f"placed {len(points)} nodes; wrote {args.out_annotations} and {args.out_graph}")
    return 0


def _run_browser(args: argparse.Namespace) -> int:
    from ..annotate_web import AnnotationSession
    from ..errors import InputError

    if args.snap_radius < 0:
        raise InputError("--snap-radius", f"must be >= 0 pixels, got {args.snap_radius:g}")
    if not 0 <= args.port <= 65535:
        raise InputError("--port", f"must be 0..65535, got {args.port}")
    if not args.video.is_file():
        raise InputError(args.video, "video file not found")
    out = args.out or args.video.parent / f"{args.video.stem}_annotation"
    session = AnnotationSession(args.video, out, snap_radius_px=args.snap_radius)

    def on_save(res: dict) -> None:
        print(f"wrote {res['annotations']} and {res['graph']} ({res['n_nodes']} nodes, {res['n_bends']} bends)")
        print(f"next: {res['next']}", flush=True)

    serve_until_finished(session, args.port, on_save, open_in_browser=not args.no_browser, announce=(
        f"annotate {args.video} in your browser: {{url}}",
        f"(writes {out}/annotations.json and graph.json; press Save & finish or Ctrl+C when done)"))
    if not session.saves:
        print("nothing saved", file=sys.stderr)
        return 1
    return 0


def serve_until_finished(session, port: int, on_save, open_in_browser: bool, announce=()) -> None:
    """Serve a browser session (``rce annotate``, ``rce review``) on localhost ``port`` until the page says it is
    finished or Ctrl+C: print the ``announce`` lines (``{url}`` filled in), open the page where asked, and close
    the server and the session whatever happens."""
    import threading

    from ..annotate_web import make_server
    server = make_server(session, port, on_save=on_save)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    for line in announce:
        print(line.replace("{url}", server.url), flush=True)
    if open_in_browser:
        open_browser(server.url)
    try:
        session.finished.wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.shutdown()
        server.server_close()
        session.close()


def open_browser(url: str) -> None:
    """Open ``url`` in a graphical browser if this session has a display (never a terminal browser)."""
    import webbrowser
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return
    try:
        webbrowser.open(url, new=2)
    except webbrowser.Error:
        pass
