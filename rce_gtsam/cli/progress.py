"""Progress on stderr for the long commands (``analyze``, ``diagnose``, ``run``) and the wall clock they report.

:class:`Steps` is one tqdm bar over a command's named steps (load, smooth, bending, fit, bootstrap,
diagnosis, figures, ...): the bar names the step in progress and its elapsed time keeps ticking while a
step runs (a step such as the diagnosis can take tens of seconds without reporting anything itself).
When stderr is not a terminal (a log file, a pipe, a batch system) it writes plain lines instead, one per
step as it starts, with the time so far, flushed at once: no carriage-return clutter, and a log shows where a
30-50 s run is. ``--quiet`` writes nothing; ``RCE_PROGRESS=1`` forces the bar (tests of the bar itself),
``RCE_PROGRESS=0`` silences both.

:func:`process_seconds` is the wall time since the Python process started (imports included): the total a
command prints is the time the user waited.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from contextlib import contextmanager

#: perf_counter() when this module was imported: the fallback start when /proc is not available.
_IMPORTED_AT = time.perf_counter()


def process_seconds() -> float:
    """Seconds since this process started (Linux: from /proc; elsewhere: since the CLI was imported)."""
    try:
        with open("/proc/self/stat") as f:
            start_ticks = float(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        return max(uptime - start_ticks / os.sysconf("SC_CLK_TCK"), time.perf_counter() - _IMPORTED_AT)
    except (OSError, ValueError, IndexError):
        return time.perf_counter() - _IMPORTED_AT


def add_quiet_argument(p: argparse.ArgumentParser, *aliases: str) -> None:
    """``--quiet`` (and any older ``aliases`` such as ``--no-progress``): no progress bars."""
    p.add_argument("--quiet", "-q", *aliases, action="store_true", dest="quiet",
                   help="no progress bars on stderr (they are drawn only when stderr is a terminal)")


def progress_enabled(quiet: bool) -> bool:
    """Whether to draw progress bars: not with ``--quiet``; on a terminal, or when ``RCE_PROGRESS=1``."""
    return progress_mode(quiet) == "bar"


def progress_mode(quiet: bool) -> str | None:
    """How to show progress on stderr: ``"bar"`` (a terminal, or ``RCE_PROGRESS=1``), ``"lines"`` (plain
    flushed lines, when stderr is a log file or pipe), or None (``--quiet``, or ``RCE_PROGRESS=0``)."""
    if quiet or os.environ.get("RCE_PROGRESS") == "0":
        return None
    if os.environ.get("RCE_PROGRESS") == "1":
        return "bar"
    try:
        return "bar" if sys.stderr.isatty() else "lines"
    except (AttributeError, ValueError):  # a replaced or closed stderr
        return "lines"


def progress_line(command: str, text: str) -> None:
    """One plain progress line on stderr, flushed (``"rce run: smooth (3.1 s)"``)."""
    print(f"rce {command}: {text}", file=sys.stderr, flush=True)


class Steps:
    """A tqdm bar over named steps on stderr.

    ``steps``: the step names in order (their count is the bar's total). Use ``with steps.step("smooth"):``
    around each step, or :meth:`callback` as a ``progress(name)`` hook that starts the named step (the
    previous one then counts as done). ``enabled``: True or ``"bar"`` draws the bar, ``"lines"`` writes one
    plain line per step (:func:`progress_mode`), False or None nothing at all.
    """

    def __init__(self, command: str, steps: list[str], enabled: bool | str | None = True):
        self.enabled = bool(enabled)
        self.lines = enabled == "lines"
        self.names = list(steps)
        self.bar = None
        self._current: str | None = None
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None
        self._command = command
        self._t0 = time.perf_counter()
        if self.enabled and not self.lines:
            from tqdm import tqdm
            self.bar = tqdm(total=len(self.names), desc=command, unit="step", file=sys.stderr, leave=False,
                            dynamic_ncols=True, bar_format="{desc}: {n_fmt}/{total_fmt} steps |{bar:20}| "
                                                           "{elapsed}{postfix}")
            self._ticker = threading.Thread(target=self._tick, daemon=True)
            self._ticker.start()

    def _tick(self) -> None:
        while not self._stop.wait(0.5):
            bar = self.bar
            if bar is not None:
                bar.refresh()

    def start(self, name: str) -> None:
        """Mark the previous step done and show ``name`` as the step in progress."""
        if self.lines:
            i = self.names.index(name) + 1 if name in self.names else "?"
            progress_line(self._command, f"[{i}/{len(self.names)}] {name} "
                                         f"({time.perf_counter() - self._t0:.1f} s so far)")
            self._current = name
            return
        if self.bar is None:
            return
        if self._current is not None:
            self.bar.update(1)
        self._current = name
        self.bar.set_description_str(f"{self._command}: {name}", refresh=True)

    def callback(self, name: str) -> None:
        """``progress(name)`` hook for :func:`rce_gtsam.pipeline.analyze`."""
        self.start(name)

    @contextmanager
    def step(self, name: str):
        self.start(name)
        yield

    def close(self) -> None:
        """Finish the bar and erase it (the command's summary follows on stdout)."""
        self._stop.set()
        if self.lines and self._current is not None:
            self._current = None
            progress_line(self._command, f"steps done ({time.perf_counter() - self._t0:.1f} s)")
        if self.bar is not None:
            bar, self.bar = self.bar, None
            bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
