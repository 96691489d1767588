"""Checks of command-line input that run before any work starts.

Every function raises :class:`~rce_gtsam.errors.InputError` naming the option, file, row or node at fault,
so ``rce`` prints one line and exits with code 2 before it smooths, tracks or bootstraps anything:

* :func:`check_output_dir` / :func:`check_output_file` — an output location must be creatable and
  writable: not a file where a folder is wanted (or the reverse), not under a file, not in a read-only folder.
* :func:`check_seed`, :func:`check_count` — integer options in range (never silently coerced).
* :func:`check_tracks_span` — the clip must be long enough for the preset's correlation length (the
  first frame must be 0: :func:`rce_gtsam.tracks.read_tracks_table` refuses others, naming the row).
* :func:`check_graph_has_bend` — a graph with no (grandparent, joint, child) triplet has nothing to fit.
* :func:`check_folds` — ``diagnose --folds K``: 2 <= K <= frames // block length.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .errors import InputError

from .quality import MIN_BLOCKS  # the shortest clip, in block lengths (frames)


def _first_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _writable(folder: Path) -> bool:
    """Whether a file can really be created in ``folder`` (a probe file, deleted at once: permission bits
    say nothing for root or on a read-only mount)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def _check_parent_chain(path: Path, option: str) -> None:
    """The nearest existing ancestor of ``path`` must be a writable folder."""
    anchor = _first_existing(path.parent if path.parent != Path("") else Path("."))
    if not anchor.is_dir():
        raise InputError(option, f"{path}: {anchor} is a file, so nothing can be created under it")
    if not _writable(anchor):
        raise InputError(option, f"{path}: the folder {anchor} is not writable")


def check_output_dir(path: Path | str | None, option: str = "--out") -> None:
    """``path`` is (or can be created as) a writable folder."""
    if path is None:
        return
    path = Path(path)
    if str(path).strip() == "":
        raise InputError(option, "the output folder is an empty path")
    if path.exists():
        if not path.is_dir():
            raise InputError(option, f"{path} is an existing file, not a folder; choose a folder path")
        if not _writable(path):
            raise InputError(option, f"the folder {path} is not writable")
    _check_parent_chain(path.absolute(), option)


def check_output_file(path: Path | str | None, option: str) -> None:
    """``path`` is (or can be created as) a writable file, not a folder."""
    if path is None:
        return
    path = Path(path)
    if str(path).strip() == "" or str(path).endswith(os.sep):
        raise InputError(option, f"{str(path)!r} names a folder; give a file path")
    if path.is_dir():
        raise InputError(option, f"{path} is a folder; give a file path (e.g. {path / 'out'}{path.suffix or ''})")
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(option, f"the file {path} is not writable")
    _check_parent_chain(path.absolute(), option)


def check_distinct_outputs(*pairs: tuple[str, Path | None]) -> None:
    """Two output options may not name the same path."""
    seen: dict[Path, str] = {}
    for option, path in pairs:
        if path is None:
            continue
        key = Path(path).absolute()
        if key in seen:
            raise InputError(option, f"{path} is also given as {seen[key]}; choose two different paths")
        seen[key] = option


def check_seed(seed: int | None, option: str = "--seed") -> None:
    """A random seed is a non-negative integer (numpy's generators refuse negative ones)."""
    if seed is not None and not 0 <= seed < 2**63:
        raise InputError(option, f"a seed must be an integer between 0 and 2**63 - 1, got {seed}")


def check_count(value: int | None, option: str, minimum: int, maximum: int | None = None, what: str = "") -> None:
    """An integer option within ``[minimum, maximum]``."""
    if value is None:
        return
    if value < minimum or (maximum is not None and value > maximum):
        rng = f">= {minimum}" if maximum is None else f"between {minimum} and {maximum}"
        raise InputError(option, f"must be {rng}{what}, got {value}")


def check_tracks_span(table, source: str | Path, block_length: int) -> None:
    """A validated tracks table (:func:`rce_gtsam.tracks.read_tracks_table`, which also refuses a first
    frame other than 0) must span at least ``MIN_BLOCKS * block_length`` frames."""
    check_clip_length(int(table["frame"].max()) + 1, source, block_length, "column 'frame'")


def check_clip_length(n: int | None, source, block_length: int, where: str | None = None) -> None:
    """A clip of ``n`` frames (None: unknown, not checked) is long enough to estimate kappa."""
    need = MIN_BLOCKS * int(block_length)
    if n is not None and n < need:
        raise InputError(source, f"the clip spans only {n} frames; kappa needs at least {need} "
                                 f"({MIN_BLOCKS} blocks of the preset's {block_length}-frame correlation length, "
                                 "compliance.block_length)", where)


def check_graph_has_bend(graph) -> None:
    """A graph needs at least one bend (grandparent -> joint -> child) for a response to fit."""
    if not graph.bends:
        raise InputError(graph.source, f"the graph has {len(graph.edges)} edge(s) and no bend: a bend needs three "
                                       "nodes in a row (grandparent -> joint -> child), so at least 3 nodes are "
                                       "needed; kappa is measured from bends")


def check_bends_observed(table, graph, source, block_length: int) -> None:
    """At least one bend must have its three nodes observed together in ``MIN_BLOCKS * block_length`` frames
    (otherwise every kappa would rest on too few frames, or on none)."""
    if "visible" in table.columns:
        table = table[table["visible"] == 1]
    frames = {n: set(g) for n, g in table.groupby("point_id")["frame"]}
    need = MIN_BLOCKS * int(block_length)
    best, best_bend = -1, None
    for bend in graph.bends:
        common = len(set.intersection(*(frames.get(n, set()) for n in bend.nodes)))
        if common > best:
            best, best_bend = common, bend
        if common >= need:
            return
    if best_bend is not None:
        raise InputError(source, f"no bend has its three nodes observed together in {need} frames (the best, "
                                 f"{'-'.join(map(str, best_bend.nodes))}, in {best}); kappa needs at least {need} "
                                 f"({MIN_BLOCKS} blocks of compliance.block_length)")


def check_folds(folds: int, n_frames: int, block_length: int) -> None:
    """``--folds K``: 2 <= K <= n_frames // block_length (test blocks of at least one block length)."""
    top = max(2, n_frames // max(int(block_length), 1))
    check_count(folds, "--folds", 2, top,
                f" (the {n_frames} frames make at most {top} test blocks of >= {block_length} frames)")


def check_analysis_inputs(tracks_path: Path, graph_path: Path, preset) -> tuple:
    """Read the graph and tracks (cheap) and check what the analysis needs of them, before it runs;
    returns (graph, validated tracks table, :class:`~rce_gtsam.tracks.Tracks`) so the caller need not read
    them again."""
    from .graph import load_graph
    from .tracks import read_tracks_table, tracks_from_table

    graph = load_graph(graph_path)
    table = read_tracks_table(tracks_path)
    tracks = tracks_from_table(table, graph, source=str(tracks_path))
    check_graph_has_bend(graph)
    check_tracks_span(table, tracks_path, preset.compliance.block_length)
    check_bends_observed(table, graph, tracks_path, preset.compliance.block_length)
    return graph, table, tracks


def check_command_options(args, out_dir_option: str | None = "--out") -> None:
    """The options most commands share, checked before any work: seed, bootstrap count, output paths
    (``--out`` folder or file, ``--json``, ``--rerun``, ``--figures``), effect lists."""
    check_seed(getattr(args, "seed", None))
    check_count(getattr(args, "bootstrap", None), "--bootstrap", 0, what=" resamples (0 disables the CIs)")
    check_count(getattr(args, "max_frames", None), "--max-frames", 1)
    for option in ("effects", "candidates"):
        value = getattr(args, option, None)
        if isinstance(value, str) and not [v for v in value.split(",") if v.strip()]:
            raise InputError(f"--{option}", "the list is empty; name at least one effect, or omit the option")
    if out_dir_option is not None:
        check_output_dir(getattr(args, "out", None), out_dir_option)
    outputs = [(out_dir_option, getattr(args, "out", None))] if out_dir_option else []
    for attr, option in (("json_path", "--json"), ("rerun", "--rerun")):
        check_output_file(getattr(args, attr, None), option)
        outputs.append((option, getattr(args, attr, None)))
    check_output_dir(getattr(args, "figures", None), "--figures")
    check_distinct_outputs(*outputs)
