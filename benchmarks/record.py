"""Save a benchmark's measured table as a validation record the documentation renders.

The documentation's *Validation* page is generated from the records in ``docs/validation/*.json`` at build
time (``tools/docs_hooks.py``), so no measured number is typed into the docs by hand. A benchmark calls
:func:`save_record` at its end; re-running the benchmark rewrites its record.

Record schema (one JSON object per file, ``docs/validation/<name>.json``):

``schema``
    ``1`` (this format).
``title``
    One line: what was measured (the page's section heading).
``command``
    The shell command that re-measures it, run from the repository root.
``date``
    ISO date (UTC) of the measurement, ``YYYY-MM-DD``.
``description``
    A few sentences: the data, what each column means, how to read it (plain text, may be ``""``).
``columns``
    The column names, in order; each may carry its unit in brackets, e.g. ``"median error (px)"``.
``rows``
    A list of rows, each a list as long as ``columns``; numbers are shown as saved (round them in the
    benchmark), strings as they are.
``notes``
    Optional list of one-line remarks shown under the table.

Example::

    from benchmarks.record import save_record
    save_record("quality", title="...", command="python benchmarks/bench_quality.py --seeds 5",
                columns=["noise", "segments", "not ok"], rows=[["default", 90, 26]])
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import re
from pathlib import Path

#: Where the documentation looks for records.
RECORD_DIR = Path(__file__).resolve().parents[1] / "docs" / "validation"
SCHEMA = 1
REQUIRED = ("schema", "title", "command", "date", "description", "columns", "rows")


def validate_record(record: dict, where: str = "record") -> None:
    """Raise ``ValueError`` naming ``where`` and the field when ``record`` does not follow the schema."""
    missing = [k for k in REQUIRED if k not in record]
    if missing:
        raise ValueError(f"{where}: missing field(s) {', '.join(missing)}")
    if record["schema"] != SCHEMA:
        raise ValueError(f"{where}: schema {record['schema']!r}, expected {SCHEMA}")
    for key in ("title", "command", "date", "description"):
        if not isinstance(record[key], str):
            raise ValueError(f"{where}: {key} must be a string")
    if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", record["date"]):
        raise ValueError(f"{where}: date must be YYYY-MM-DD, got {record['date']!r}")
    cols = record["columns"]
    if not cols or not all(isinstance(c, str) for c in cols):
        raise ValueError(f"{where}: columns must be a non-empty list of strings")
    for i, row in enumerate(record["rows"]):
        if not isinstance(row, list) or len(row) != len(cols):
            raise ValueError(f"{where}: row {i} must be a list of {len(cols)} values")
        for v in row:
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"{where}: row {i} holds a non-finite number")
            if not isinstance(v, (str, int, float)) or isinstance(v, bool):
                raise ValueError(f"{where}: row {i} holds {v!r}; only strings and numbers are allowed")
    if not isinstance(record.get("notes", []), list):
        raise ValueError(f"{where}: notes must be a list of strings")


def save_record(name: str, *, title: str, command: str, columns: list[str], rows: list[list],
                description: str = "", notes: list[str] | None = None, date: str | None = None,
                directory: str | Path | None = None) -> Path:
    """Write ``<directory>/<name>.json`` (default :data:`RECORD_DIR`, or ``$RCE_RECORD_DIR``) atomically.

    ``name``: file stem (letters, digits, ``_``, ``-``). ``rows``: measured values, already rounded to the
    decimals the benchmark can support. ``date``: default today (UTC). Returns the path written."""
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise ValueError(f"record name {name!r}: use letters, digits, '_' and '-'")
    record = {"schema": SCHEMA, "title": title, "command": command,
              "date": date or _dt.datetime.now(_dt.timezone.utc).date().isoformat(),
              "description": description, "columns": list(columns), "rows": [list(r) for r in rows],
              "notes": list(notes or [])}
    validate_record(record, name)
    out_dir = Path(directory) if directory else record_dir()
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
    os.replace(tmp, path)
    return path


def record_dir() -> Path:
    """The folder :func:`save_record` writes to by default: ``$RCE_RECORD_DIR``, else :data:`RECORD_DIR`."""
    return Path(os.environ.get("RCE_RECORD_DIR") or RECORD_DIR)


def load_record(name: str) -> dict:
    """Record ``name`` as saved (in :func:`record_dir`), validated: for a benchmark that re-measures some of its rows
    and writes it back through :func:`save_record`."""
    path = record_dir() / f"{name}.json"
    record = json.loads(path.read_text())
    validate_record(record, str(path))
    return record


def load_records(directory: str | Path = RECORD_DIR) -> list[tuple[str, dict]]:
    """(stem, record) of every ``*.json`` in ``directory``, sorted by name, each validated."""
    out = []
    for path in sorted(Path(directory).glob("*.json")):
        record = json.loads(path.read_text())
        validate_record(record, str(path))
        out.append((path.stem, record))
    return out
