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
    # a node seen in one frame is no longer an input error: its segments are dropped (test_quality_support.py)
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


#: the first bytes of files a user passes as the tracks CSV by mistake (the video, a figure)
NOT_A_CSV = {"png": b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256)),
             "mp4": b"\x00\x00\x00\x20ftypisom\x00\x00\x02\x00isomiso2avc1mp41" + bytes(range(256)),
             "latin1": "point_id,frame,x,y\n0,0,1.0,2.0 caf\xe9\n".encode("latin-1") * 3}


@pytest.fixture(scope="module")
def analysis_folder(tmp_path_factory):
    """A real analysis output folder (the sample, no CIs, no figures) for ``rce view``."""
    from pathlib import Path
    sample = Path(__file__).resolve().parents[1] / "data" / "sample"
    out = tmp_path_factory.mktemp("view") / "out"
    assert main(["analyze", str(sample / "tracks.csv"), str(sample / "graph.json"), "--out", str(out),
                 "--bootstrap", "0", "--no-figures", "--quiet"]) == 0
    return out


@pytest.mark.parametrize("kind", list(NOT_A_CSV))
@pytest.mark.parametrize("command", ["analyze", "diagnose", "view"])
def test_a_video_or_image_given_as_the_tracks_csv_is_one_line_exit_2(tmp_path, capsys, kind, command,
                                                                      analysis_folder):
    """Every command that reads a tracks CSV names the file in one line (exit 2), not a pandas
    UnicodeDecodeError traceback."""
    _, graph = write_case(tmp_path)
    bad = tmp_path / f"clip.{kind}"
    bad.write_bytes(NOT_A_CSV[kind])
    argv = {"analyze": ["analyze", str(bad), str(graph), "--out", str(tmp_path / "o")],
            "diagnose": ["diagnose", str(bad), str(graph), "--json", str(tmp_path / "d.json")],
            "view": ["view", str(analysis_folder), "--tracks", str(bad), "--rrd", str(tmp_path / "v.rrd")]}[command]
    capsys.readouterr()
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and "UnicodeDecodeError" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert bad.name in err and ("not a tracks CSV" in err or "UTF-8" in err), err
    assert not (tmp_path / "o").exists() and not (tmp_path / "v.rrd").exists()


def test_a_batch_row_with_a_video_as_tracks_fails_naming_the_file(tmp_path):
    from rce_gtsam.tracks import read_tracks_table
    from rce_gtsam.errors import InputError
    bad = tmp_path / "clip.mp4"
    bad.write_bytes(NOT_A_CSV["mp4"])
    with pytest.raises(InputError, match="clip.mp4: this is an MP4/MOV video, not a tracks CSV"):
        read_tracks_table(bad)  # the batch worker reads a row's tracks through this (batch/process.py)
