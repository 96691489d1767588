"""Malformed inputs give a clear error that names the file and the row or node, and write nothing."""

from __future__ import annotations

import json

import pytest

from rce_gtsam.cli import main

GOOD_GRAPH = {"root": 0, "edges": [[0, 1], [1, 2], [2, 3]]}


def good_rows(nodes=(0, 1, 2, 3), frames=range(5)):
    return [f"{n},{f},{100 + 10 * n + 0.1 * f},{200 - 10 * n}" for n in nodes for f in frames]


def write_case(tmp_path, rows=None, graph=None, header="point_id,frame,x,y", raw_tracks=None, raw_graph=None):
    tracks = tmp_path / "tracks.csv"
    gfile = tmp_path / "graph.json"
    if raw_tracks is not None:
        tracks.write_text(raw_tracks)
    else:
        tracks.write_text("\n".join([header, *(rows if rows is not None else good_rows())]) + "\n")
    gfile.write_text(raw_graph if raw_graph is not None else json.dumps(graph or GOOD_GRAPH))
    return tracks, gfile


CASES = {
    # name: (kwargs for write_case, which file the message must name, text the message must contain)
    "cycle in graph": (dict(graph={"root": 0, "edges": [[0, 1], [2, 3], [3, 2]]}), "graph", "cycle"),
    "two roots": (dict(graph={"root": 0, "edges": [[0, 1], [5, 6]]}), "graph", "more than one root"),
    "two parents": (dict(graph={"root": 0, "edges": [[0, 1], [0, 2], [1, 3], [2, 3]]}), "graph", "node 3"),
    "self loop": (dict(graph={"root": 0, "edges": [[0, 1], [1, 1]]}), "graph", "self-loop"),
    "invalid json": (dict(raw_graph='{"root": 0, "edges": [[0, 1],'), "graph", "not valid JSON"),
    "graph missing key": (dict(raw_graph='{"edges": [[0, 1]]}'), "graph", "missing key 'root'"),
    "node without tracks": (dict(rows=good_rows(nodes=(0, 1, 2))), "tracks", "node 3"),
    "graph edge to unknown node": (dict(graph={"root": 0, "edges": [[0, 1], [1, 2], [2, 3], [3, 99]]}),
                                   "tracks", "node 99"),
    "NaN coordinate": (dict(rows=good_rows() + ["3,7,nan,5.0"]), "tracks", "line"),
    "infinite coordinate": (dict(rows=good_rows() + ["3,7,inf,5.0"]), "tracks", "finite"),
    "non-numeric coordinate": (dict(rows=good_rows() + ["3,7,abc,5.0"]), "tracks", "'abc'"),
    "duplicate rows": (dict(rows=good_rows() + ["2,3,1.0,2.0"]), "tracks", "duplicate row for point 2 at frame 3"),
    "non-integer frame": (dict(rows=good_rows() + ["1,7.5,1.0,2.0"]), "tracks", "integers"),
    "negative frame": (dict(rows=good_rows() + ["1,-1,1.0,2.0"]), "tracks", ">= 0"),
    "empty file": (dict(raw_tracks=""), "tracks", "empty"),
    "header only": (dict(raw_tracks="point_id,frame,x,y\n"), "tracks", "no rows"),
    "missing column": (dict(header="point_id,frame,x", rows=[r.rsplit(",", 1)[0] for r in good_rows()]),
                       "tracks", "missing column"),
    "single-frame track": (dict(rows=[r for r in good_rows() if not r.startswith("3,") or r.startswith("3,0,")]),
                           "tracks", "only 1 frame"),
    "bad visible flag": (dict(header="point_id,frame,x,y,visible", rows=[r + ",2" for r in good_rows()]),
                         "tracks", "'visible' must be 0 or 1"),
    "frames not starting at 0": (dict(rows=good_rows(frames=range(1000, 1005))), "tracks", "the first frame is 1000"),
    "non-positive sigma": (dict(header="point_id,frame,x,y,sigma_px", rows=[r + ",0" for r in good_rows()]),
                           "tracks", "sigma_px must be > 0"),
}


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_is_a_clear_error_and_writes_nothing(tmp_path, capsys, name):
    kwargs, culprit, needle = CASES[name]
    tracks, graph = write_case(tmp_path, **kwargs)
    out = tmp_path / "out"
    code = main(["analyze", str(tracks), str(graph), "--out", str(out), "--bootstrap", "0"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert (tracks if culprit == "tracks" else graph).name in err, err
    assert needle in err, err
    assert not out.exists(), "a failed run must not create its output folder"
    assert not list(tmp_path.glob(".out.*")), "no temporary folder may be left behind"


def test_error_names_the_line_of_a_bad_row(tmp_path, capsys):
    rows = good_rows()
    rows[6] = "1,1,1.0,oops"
    tracks, graph = write_case(tmp_path, rows=rows)
    assert main(["analyze", str(tracks), str(graph), "--out", str(tmp_path / "o")]) == 2
    assert "line 8" in capsys.readouterr().err  # header is line 1, rows[6] is line 8


def test_missing_file(tmp_path, capsys):
    _, graph = write_case(tmp_path)
    assert main(["analyze", str(tmp_path / "nope.csv"), str(graph), "--out", str(tmp_path / "o")]) == 2
    assert "nope.csv" in capsys.readouterr().err


def test_points_outside_the_graph_are_ignored(tmp_path):
    from rce_gtsam import load_graph, load_tracks
    tracks, graph = write_case(tmp_path, rows=good_rows() + good_rows(nodes=(42,)))
    t = load_tracks(tracks, load_graph(graph))
    assert 42 not in t.node_ids and t.xy.shape == (4, 5, 2)


def test_invisible_rows_are_unobserved(tmp_path):
    from rce_gtsam import load_graph, load_tracks
    rows = [r + (",0" if r.startswith("2,3,") else ",1") for r in good_rows()]
    tracks, graph = write_case(tmp_path, header="point_id,frame,x,y,visible", rows=rows)
    t = load_tracks(tracks, load_graph(graph))
    assert not t.observed[t.index(2), 3] and t.observed.sum() == 19
