"""Atomic output writing with ordinary file modes.

Every command writes through a temporary file or folder beside its target and renames it into place, so a
failure never leaves a half-written output. :mod:`tempfile` creates those temporaries private (files 0600,
folders 0700); the helpers here give them the modes an ordinary ``open()`` / ``mkdir`` would (0666 / 0777
minus the umask: usually 0644 / 0755) before they become outputs.

Overwrite policy shared by every command: a command replaces the files it writes and leaves every other
file in the output folder alone (:func:`publish`).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def ordinary_mode(path: str | Path) -> None:
    """Give a temporary file or folder the mode ``open()`` / ``mkdir`` would have given it."""
    path = Path(path)
    os.chmod(path, (0o777 if path.is_dir() else 0o666) & ~_umask())


def temp_file_beside(path: str | Path, suffix: str = ".tmp") -> Path:
    """An empty temporary file in ``path``'s folder (created), with an ordinary mode; the caller renames it
    onto ``path`` (``os.replace``) or deletes it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    ordinary_mode(tmp)
    return Path(tmp)


def temp_dir_beside(path: str | Path) -> Path:
    """An empty temporary folder next to ``path`` (its parent created), with an ordinary mode."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    ordinary_mode(tmp)
    return tmp


def write_text_atomic(text: str, path: str | Path) -> Path:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    tmp = temp_file_beside(path)
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def publish(tmp: Path, out_dir: str | Path, stale: Iterable[str] = ()) -> list[Path]:
    """Move every file under the temporary folder ``tmp`` into ``out_dir`` (same relative paths), replacing
    files of the same name and leaving other files alone; remove the files named in ``stale`` (relative
    paths this command writes on other runs, e.g. ``video.mp4`` without ``--video``) when this run did not
    write them; delete ``tmp``. Returns the relative paths written."""
    out_dir = Path(out_dir)
    written = sorted(p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file())
    try:
        if not out_dir.exists():
            os.replace(tmp, out_dir)
            return written
        if not out_dir.is_dir():
            from .errors import InputError
            raise InputError(out_dir, "output path exists and is not a folder")
        for rel in written:
            dest = out_dir / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / rel, dest)
        names = {str(r) for r in written}
        for rel in stale:
            if rel not in names:
                (out_dir / rel).unlink(missing_ok=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written
