"""Errors a user sees.

Every problem with user input is an :class:`InputError` that names the file and, where it
can, the row, node or key at fault, so the message alone says what to fix.
"""

from __future__ import annotations

from pathlib import Path


class RceError(Exception):
    """Base class of every error rce_gtsam raises on purpose."""


class InputError(RceError, ValueError):
    """Malformed or inconsistent user input (tracks CSV, graph JSON, annotations, video).

    Parameters
    ----------
    source:
        The file (or a short description of the in-memory object) the problem is in.
    message:
        What is wrong and, if possible, how to fix it.
    where:
        Optional location inside the source: ``"row 17"``, ``"node 4"``, ``"edge [3, 2]"``.
    """

    def __init__(self, source: str | Path, message: str, where: str | None = None):
        self.source = str(source)
        self.where = where
        self.message = message
        location = f" ({where})" if where else ""
        super().__init__(f"{self.source}{location}: {message}")


class MissingDependencyError(RceError, ImportError):
    """An optional dependency (pyrealsense2, libusb, onnxruntime model file) is not available."""
