"""The ``rce`` command line: :mod:`.app` builds the parser from one module per sub-command.

``analyze``, ``diagnose``, ``track``, ``annotate``, ``simulate``, ``run``, ``view`` and ``batch`` each live in a
module of this folder exposing ``register(subparsers)``; :mod:`.preset_args`, :mod:`.live_args`,
:mod:`.progress` and :mod:`.wording` are what they share, :mod:`.figure_worker` draws figures in a child process.
"""

from .app import build_parser, main

__all__ = ["build_parser", "main"]
