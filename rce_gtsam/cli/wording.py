"""What the commands say: the diagnosis' advice in command-line words, and the shared ``--candidates`` option.

The diagnosis explains a verdict for Python users ("Fit the model with Delay()"); a command-line user adds
an effect with ``rce analyze --effects delay``. :func:`cli_wording` rewrites the one into the other (the
class names come from :data:`rce_gtsam.effects.CANDIDATES`, so a new effect is covered without an edit here).
"""

from __future__ import annotations

import argparse
import re
import sys

_FIT_WITH = re.compile(r"Fit (?:the model )?with (\w+)\(\)")
_FIT_AND_READ = re.compile(r"Fit (?:the model )?with (\w+)\(\) and read kappa from the extended fit\.")


def cli_wording(text: str, written: str | None = None) -> str:
    """``text`` with every "Fit [the model] with Name()" replaced by the ``rce analyze --effects`` command; with
    ``written`` (the compliance_summary.csv column this command wrote the extended model's kappa to, ``rce run``),
    "Fit the model with Name() and read kappa from the extended fit." says so instead: no second command."""
    if not text or "()" not in text:
        return text
    from ..effects import CANDIDATES
    name_of = {factory.__name__: name for name, factory in CANDIDATES.items()}
    if written:
        text = _FIT_AND_READ.sub(lambda m: (f"This run fitted it: kappa from the extended fit, with its own "
                                            f"intervals, is {written} in compliance_summary.csv."
                                            if m.group(1) in name_of else m.group(0)), text)

    def repl(m: re.Match) -> str:
        name = name_of.get(m.group(1))
        return f"Fit it with `rce analyze TRACKS GRAPH --effects {name}`" if name else m.group(0)
    return _FIT_WITH.sub(repl, text)


def cli_wording_json(data: dict, written: str | None = None) -> dict:
    """The diagnosis JSON / figure mapping with its ``explanation`` and ``report`` texts in CLI wording
    (``written``: see :func:`cli_wording`)."""
    for key in ("explanation", "report"):
        if isinstance(data.get(key), str):
            data[key] = cli_wording(data[key], written)
    return data


def rce_invocation() -> list[str]:
    """How to start ``rce`` again from a shell, for the commands a command prints for the user to run next:
    ``["rce"]`` when ``rce`` is on PATH; otherwise the running executable by its absolute path (a virtual
    environment's ``.venv/bin/rce`` used without activating it), or ``python -m rce_gtsam.cli`` with this
    interpreter's path when the CLI was started that way."""
    import os
    import shutil
    if shutil.which("rce"):
        return ["rce"]
    exe = sys.argv[0] if sys.argv and sys.argv[0] else ""
    if os.path.basename(exe) == "rce" and os.path.isfile(exe):
        return [os.path.abspath(exe)]
    return [sys.executable, "-m", "rce_gtsam.cli"]


#: The built-in effects the diagnosis tries by default, as the help lists them (written out, not imported: the
#: effects package takes a second to import and ``--help`` answers in well under that; a test keeps it equal to
#: :func:`rce_gtsam.effects.names`).
DEFAULT_CANDIDATES = "delay,dynamics,second_mode,offset,nonlinear,resonances,out_of_plane"


def add_candidates_argument(p: argparse.ArgumentParser, command: str) -> None:
    """``--candidates A,B``: the effects the diagnosis tests (``--effects`` is the deprecated old name here;
    in ``rce analyze`` ``--effects`` adds terms to the fitted model)."""
    p.add_argument("--candidates", default=None, metavar="A,B",
                   help="effects the diagnosis tests, comma-separated (default: every effect in the library: "
                        + DEFAULT_CANDIDATES + ")")
    p.add_argument("--effects", default=None, dest="effects_deprecated", help=argparse.SUPPRESS)
    p.set_defaults(_command_name=command)


def candidates_from_args(args: argparse.Namespace) -> str | None:
    """The ``--candidates`` value; the deprecated ``--effects`` is accepted with a one-line note on stderr."""
    old = getattr(args, "effects_deprecated", None)
    if old is not None:
        print(f"rce {args._command_name}: note: --effects is now --candidates here (the effects to test); "
              f"--effects adds effects to the model only in `rce analyze`", file=sys.stderr)
        if args.candidates is None:
            return old
    return args.candidates
