"""Draw the figures in a second process while the analysis runs, so they do not hold the user up.

``rce analyze`` starts :class:`FigureWorker` first thing (a fork of the still-small CLI process); the worker
imports matplotlib while the main process imports the numerical stack and analyses. Just before the
bootstrap the main process hands over the result without CIs and the worker draws every figure that does
not need them; after the bootstrap it hands over the full result for the rest. Jobs run in order; each job
is a module-level function plus its arguments (pickled through a pipe, ~12 MB for plant 1), and its return
value or its error comes back. Where ``fork`` is not available the jobs run in the calling process instead.
"""

from __future__ import annotations

import multiprocessing
import traceback
from pathlib import Path


def _serve(conn) -> None:
    """Worker loop: import the plotting stack once, then run jobs until told to stop (None)."""
    try:
        from ..viz import figures, overlays  # noqa: F401  (warm up matplotlib while the parent computes)
    except Exception:  # noqa: BLE001 - reported when a job needs them
        pass
    while True:
        try:
            job = conn.recv()
        except EOFError:
            return
        if job is None:
            return
        fn, args, kwargs = job
        try:
            conn.send(("ok", fn(*args, **kwargs)))
        except BaseException as exc:  # noqa: BLE001 - the parent re-raises it
            conn.send(("error", (exc, traceback.format_exc())))


class FigureWorker:
    """A worker process that runs plotting jobs in submission order (see module docstring)."""

    def __init__(self):
        self._pending = 0
        self._proc = self._conn = None
        self._inline: list = []
        try:
            ctx = multiprocessing.get_context("fork")
        except ValueError:
            return
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(child,), daemon=True, name="rce-figures")
        self._proc.start()
        child.close()

    def submit(self, fn, *args, **kwargs) -> None:
        """Queue ``fn(*args, **kwargs)``; its result comes back from :meth:`results`."""
        if self._proc is None:
            self._inline.append((fn, args, kwargs))
            return
        self._conn.send((fn, args, kwargs))
        self._pending += 1

    def results(self) -> list:
        """Wait for every submitted job; their return values in order. A job's error is raised here."""
        out = []
        if self._proc is None:
            jobs, self._inline = self._inline, []
            return [fn(*a, **k) for fn, a, k in jobs]
        while self._pending:
            try:
                status, value = self._conn.recv()
            except EOFError:
                raise RuntimeError("the figure worker process died") from None
            self._pending -= 1
            if status == "error":
                exc, tb = value
                raise RuntimeError(f"drawing the figures failed:\n{tb}") from exc
            out.append(value)
        return out

    def close(self) -> None:
        if self._proc is not None:
            try:
                self._conn.send(None)
            except (BrokenPipeError, OSError):
                pass
            self._proc.join(timeout=5)
            if self._proc.is_alive():
                self._proc.terminate()
            self._proc = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def draw_analysis_figures(result, out_dir: str | Path, names, overlay_names, first_frame=None) -> dict[str, str]:
    """Job: the named analysis figures and overlays of ``result`` into ``out_dir``; {file name: path}."""
    from ..viz.figures import write_figures
    from ..viz.overlays import write_overlays

    out = {k: str(v) for k, v in write_figures(result, out_dir, names=names).items()}
    out.update({k: str(v) for k, v in write_overlays(result, out_dir, first_frame=first_frame,
                                                         names=overlay_names).items()})
    return out
