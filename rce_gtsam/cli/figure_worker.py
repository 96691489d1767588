"""Draw the figures in a second process while the analysis runs, so they do not hold the user up.

:class:`FigureWorker` forks at its first job: ``rce analyze`` submits that job (:func:`prepare_figures`:
import matplotlib and the figure modules, load the fonts) once the inputs are checked, so the worker
inherits the pipeline's modules and gets matplotlib ready while the main process loads and smooths the
tracks; the main process never imports matplotlib. Later jobs (every figure that needs no confidence
interval, sent just before the bootstrap; the figures that need the CIs; the diagnosis figures of
``rce run``) are a module-level function plus its arguments pickled through a pipe (~16 MB for plant 1,
a few ms, unpickled without new imports), sent from a thread so the main process never waits for the
worker to be free. Jobs run in order; each one's return value or error comes back. Where
``fork`` is not available the jobs run in the calling process when their results are asked for.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import pickle
import threading
import traceback
from pathlib import Path


#: How much lower the figure processes' CPU priority is than the command's (``nice`` increment).
FIGURE_NICENESS = 10


def _serve(conn, first) -> None:
    """Worker loop: run the first job (inherited through the fork), then jobs from the pipe until None.

    The worker runs at a lower CPU priority: on a machine with fewer free cores than processes, the
    analysis the user waits for goes first and the figures fill the gaps."""
    try:
        os.nice(FIGURE_NICENESS)
    except OSError:  # not permitted: keep the inherited priority
        pass
    job = first
    while True:
        if job is None:
            return
        fn, args, kwargs = job
        try:
            conn.send(("ok", fn(*args, **kwargs)))
        except BaseException as exc:  # noqa: BLE001 - the parent re-raises it
            conn.send(("error", (exc, traceback.format_exc())))
        try:
            job = conn.recv()
        except EOFError:
            return


class FigureWorker:
    """A worker process that runs plotting jobs in submission order (see module docstring)."""

    def __init__(self):
        self._pending = 0
        self._proc = self._conn = None
        self._inline: list = []
        self._sender = None  # the thread sending the latest job (see submit)
        self._send_error: BaseException | None = None

    def submit(self, fn, *args, **kwargs) -> None:
        """Queue ``fn(*args, **kwargs)``; its result comes back from :meth:`results`. The first job forks."""
        if self._proc is None and not self._inline:
            try:
                ctx = multiprocessing.get_context("fork")
            except ValueError:
                ctx = None
            if ctx is not None:
                # objects made so far are left out of later garbage collections, which would otherwise
                # touch (and so copy) every page the two processes still share after the fork
                gc.freeze()
                self._conn, child = ctx.Pipe()
                self._proc = ctx.Process(target=_serve, args=(child, (fn, args, kwargs)), daemon=True,
                                         name="rce-figures")
                self._proc.start()
                child.close()
                self._pending += 1
                return
        if self._proc is None:
            self._inline.append((fn, args, kwargs))
            return
        # A job (~16 MB for plant 1) goes through a pipe the worker drains only once it is free: send it
        # from a thread (after the previous one, keeping the order), so the caller never waits for the
        # worker; the writes release the GIL.
        previous, job = self._sender, (fn, args, kwargs)

        def send() -> None:
            if previous is not None:
                previous.join()
            try:
                self._conn.send(job)
            except BaseException as exc:  # noqa: BLE001 - raised by results()
                self._send_error = exc
        self._sender = threading.Thread(target=send, name="rce-figures-send", daemon=True)
        self._sender.start()
        self._pending += 1

    def results(self) -> list:
        """Wait for every submitted job; their return values in order. A job's error is raised here."""
        out = []
        if self._proc is None:
            jobs, self._inline = self._inline, []
            return [fn(*a, **k) for fn, a, k in jobs]
        if self._sender is not None:
            self._sender.join()
        if self._send_error is not None:
            raise RuntimeError("the figure worker process died") from self._send_error
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
            if self._sender is not None:
                self._sender.join(timeout=5)
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


def prepare_figures() -> dict[str, str]:
    """Job: import matplotlib (Agg) and the figure modules and draw one throw-away figure with text into
    memory (font loading, caches), so the figures proper start at once when the data arrive; {}."""
    import io

    from ..viz import figures, metrics, overlays, scene  # noqa: F401 - imported for the later jobs
    from ..viz.style import mpl_style, save_png
    with mpl_style() as plt:
        fig, ax = plt.subplots(figsize=(1, 1), constrained_layout=True)
        ax.set_title("κ")
        ax.set_xlabel("frame")
    save_png(fig, io.BytesIO())
    return {}


#: Relative drawing cost of each analysis figure (measured on plant 1: ~0.1 s per unit), to split them
#: between two processes.
FIGURE_COST = {"motion.png": 3, "residuals.png": 3, "bending_fit.png": 2, "compliance.png": 2,
               "kappa_overlay.png": 2, "uncertainty_overlay.png": 2, "smoothing.png": 1, "excitation.png": 1}


def split_by_cost(names, parts: int = 2) -> list[list[str]]:
    """``names`` in ``parts`` groups of about equal :data:`FIGURE_COST` (costliest first, each to the
    lightest group; unknown names cost 2)."""
    groups, load = [[] for _ in range(parts)], [0] * parts
    for n in sorted(names, key=lambda n: -FIGURE_COST.get(n, 2)):
        i = load.index(min(load))
        groups[i].append(n)
        load[i] += FIGURE_COST.get(n, 2)
    return groups


def draw_analysis_figures(result, out_dir: str | Path, names, overlay_names, first_frame=None,
                          processes: int = 1) -> dict[str, str]:
    """Job: the named analysis figures and overlays of ``result`` into ``out_dir``; {file name: path}.

    ``processes=2`` (and ``fork`` available): half of them (by :data:`FIGURE_COST`) are drawn by a child
    forked here, which has matplotlib ready and the data in memory; an error there is raised here."""
    names, overlay_names = list(names), list(overlay_names)
    if processes < 2 or len(names) + len(overlay_names) < 2 or not hasattr(os, "fork"):
        return _draw(result, out_dir, names, overlay_names, first_frame)
    mine, theirs = split_by_cost(names + overlay_names)
    read_end, write_end = os.pipe()
    gc.freeze()  # see FigureWorker.submit
    pid = os.fork()
    if pid == 0:  # the child: draw its share, send {name: path} or the error, and leave at once
        status = 1
        try:
            os.close(read_end)
            try:
                reply = ("ok", _draw(result, out_dir, [n for n in names if n in theirs],
                                     [n for n in overlay_names if n in theirs], first_frame))
            except BaseException:  # noqa: BLE001 - reported to the parent
                reply = ("error", traceback.format_exc())
            with os.fdopen(write_end, "wb") as f:
                pickle.dump(reply, f)
            status = 0
        finally:
            os._exit(status)
    os.close(write_end)
    try:
        out = _draw(result, out_dir, [n for n in names if n in mine], [n for n in overlay_names if n in mine],
                    first_frame)
    finally:
        with os.fdopen(read_end, "rb") as f:
            data = f.read()
        os.waitpid(pid, 0)
    if not data:
        raise RuntimeError("the second figure process died")
    status, value = pickle.loads(data)
    if status == "error":
        raise RuntimeError(f"drawing the figures failed:\n{value}")
    out.update(value)
    return {n: out[n] for n in names + overlay_names if n in out}


def _draw(result, out_dir, names, overlay_names, first_frame) -> dict[str, str]:
    from ..viz.figures import write_figures
    from ..viz.overlays import write_overlays

    out = {k: str(v) for k, v in write_figures(result, out_dir, names=names).items()}
    out.update({k: str(v) for k, v in write_overlays(result, out_dir, first_frame=first_frame,
                                                         names=overlay_names).items()})
    return out
