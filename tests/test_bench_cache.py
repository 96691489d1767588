"""bench_diagnose --cache: a case's pipeline output is written once, read back unchanged, never half-written."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_diagnose  # noqa: E402


def test_a_cached_case_runs_the_pipeline_once_and_reads_back_the_same(tmp_path, monkeypatch):
    calls = []
    rng = np.random.default_rng(0)
    Y, s = rng.standard_normal((4, 30)), np.linspace(0.2, 1, 4)

    def fake_case(effect, seed, frames, matrices, mult=1.0, noise_free=False, held_out=False, shape=None,
                  artifacts=None):
        calls.append((effect, seed, frames, mult, noise_free, held_out))
        return Y, None, s, np.ones(4), Y * 0.5, 1.5, ["0->1", "1->2", "2->3", "3->4"]

    monkeypatch.setattr(bench_diagnose, "case", fake_case)
    first = bench_diagnose.cached_case(str(tmp_path), "delay", 3, 30, False, 0.75)
    again = bench_diagnose.cached_case(str(tmp_path), "delay", 3, 30, False, 0.75)
    other = bench_diagnose.cached_case(str(tmp_path), "delay", 3, 30, False, 0.75, noise_free=True)
    held = bench_diagnose.cached_case(str(tmp_path), "delay", 3, 30, False, 0.75, held_out=True)
    tree = bench_diagnose.cached_case(str(tmp_path), "delay", 3, 30, False, 0.75,
                                      shape=bench_diagnose.parse_shape("branch_layout=tree,n_nodes=9"))
    from rce_gtsam.sim.artifacts import ArtifactConfig
    bench_diagnose.cached_case(str(tmp_path), "delay", 3, 30, False, 0.75,
                               artifacts=ArtifactConfig(("lag", "slide"), scale=2.0))
    assert bench_diagnose.artifact_suffix(ArtifactConfig(("lag", "slide"), 2.0)).startswith("_art-lag+slide-2-")
    assert len(calls) == 5 and calls[1][-2] is True          # the noise-free case is a different file
    assert calls[2][-1] is True                              # and so is the held-out forms and noise case
    assert sorted(p.name for p in tmp_path.iterdir()) == [   # and a recording of another shape, or with artifacts
        "delay_0.75_3_30.npz", f"delay_0.75_3_30{bench_diagnose.artifact_suffix(ArtifactConfig(('lag', 'slide'), 2.0))}.npz",
        "delay_0.75_3_30_branch_layout-tree_n_nodes-9.npz", "delay_0.75_3_30_heldout.npz",
        "delay_0.75_3_30_noisefree.npz"]
    assert tree[5] == 1.5
    assert held[5] == 1.5
    np.testing.assert_array_equal(again[0], first[0])
    assert again[1] is None and again[5] == 0.0 and again[6] == first[6]  # no weights; cached: 0 pipeline seconds
    assert other[5] == 1.5


def test_shape_text_becomes_typed_simulation_fields_and_a_bad_field_is_named():
    assert bench_diagnose.parse_shape("n_nodes=8, fps=60,branch_layout=tree") == {
        "n_nodes": 8, "fps": 60.0, "branch_layout": "tree"}
    assert bench_diagnose.parse_shape("") == {}
    for bad in ("nodes=8", "fps=", "seed=3"):
        try:
            bench_diagnose.parse_shape(bad)
        except ValueError as err:
            assert repr(bad.strip()) in str(err)
        else:  # pragma: no cover
            raise AssertionError(f"{bad!r} accepted")
