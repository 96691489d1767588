"""Where the Rerun viewer is: the one installed beside this Python (``.venv/bin/rerun``), else PATH's.

``rce`` runs from a virtual environment whose ``bin`` folder is usually not on PATH, so messages and
``--spawn`` use the viewer of the environment the CLI runs from.
"""

from __future__ import annotations

import shlex
import shutil
import sys
from pathlib import Path

from .errors import MissingDependencyError


def viewer_executable() -> str:
    """The ``rerun`` viewer of the environment this program runs from (``sys.executable``'s bin folder),
    else the one on PATH. Raises :class:`MissingDependencyError` when there is none."""
    here = Path(sys.executable).parent / ("rerun.exe" if sys.platform == "win32" else "rerun")
    if here.is_file():
        return str(here)
    found = shutil.which("rerun")
    if found:
        return found
    raise MissingDependencyError(f"no Rerun viewer beside {sys.executable} or on PATH; install it with "
                                 f"`{sys.executable} -m pip install rerun-sdk`")


def open_command(path: str | Path) -> str:
    """The shell command that opens the recording ``path`` in this environment's viewer."""
    return f"{shlex.quote(viewer_or_name())} {shlex.quote(str(path))}"


def viewer_or_name() -> str:
    """:func:`viewer_executable`, or plain ``rerun`` when there is none (for messages)."""
    try:
        return viewer_executable()
    except MissingDependencyError:
        return "rerun"


def require_display(option: str = "--spawn") -> None:
    """Raise :class:`InputError` (one line, before any work) when a native viewer window cannot open here:
    on Linux, neither ``DISPLAY`` nor ``WAYLAND_DISPLAY`` is set (the spawned viewer would exit and the
    stream would wait for it)."""
    import os
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        from .errors import InputError
        raise InputError(option, "no display to open a Rerun viewer on (neither DISPLAY nor WAYLAND_DISPLAY is "
                                 "set); save a recording (--rerun / --rrd) and open it where there is a screen, "
                                 "or stream to a viewer elsewhere with --connect HOST:PORT")
