"""The ``rce`` command line.

Each command lives in its own module that exposes ``register(subparsers)``; the module adds one
sub-parser and sets ``func`` to a callable taking the parsed ``argparse.Namespace`` and returning an
exit code. :func:`main` turns :class:`~rce_gtsam.errors.RceError` into a one-line message and exit
code 2 instead of a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import RceError

#: Modules that contribute sub-commands, in the order ``rce --help`` lists them.
COMMAND_MODULES = (
    "rce_gtsam.cli.analyze",
    "rce_gtsam.cli.diagnose",
    "rce_gtsam.cli.track",
    "rce_gtsam.cli.annotate",
    "rce_gtsam.cli.review",
    "rce_gtsam.cli.simulate",
    "rce_gtsam.cli.run",
    "rce_gtsam.cli.view",
    "rce_gtsam.cli.batch",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rce",
        description="Relative compliance of plant branches from monocular video "
                    "(tracking, GTSAM smoothing, rank-1 compliance, model diagnosis).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = int(args.func(args) or 0)
        if argv is None:
            # the process ends next: keep the garbage collector away from the numerical stack's millions of
            # objects during interpreter shutdown (1.2 s -> 0.15 s after an analysis on a loaded machine),
            # so the total a command prints is what the user waits; atexit handlers still run
            import gc
            gc.freeze()
        return code
    except RceError as exc:
        print(f"rce {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rce {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our output went away (``rce ... | head``): stop quietly, as other Unix tools do; stdout
        # is pointed at /dev/null so that the interpreter's final flush does not raise again
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
