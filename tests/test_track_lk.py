"""The default (anchored Lucas-Kanade) tracker on a synthetic textured swinging branch with a leaf occluder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rce_gtsam.errors import InputError
from rce_gtsam.graph import BranchGraph
from rce_gtsam.track import ArraySource, LKConfig, LKTracker

from track_fixtures import branch_video, rendered_simulation, truth_by_node_id


@pytest.fixture(scope="module")
def scene():
    bv = branch_video(n_frames=241, size=(320, 260), tip_amp_px=35, gust_amp_px=12, seed=1)
    rng = np.random.default_rng(0)  # sensor noise, so LK is not fed a perfect render
    frames = np.clip(bv.frames + rng.normal(0, 4, bv.frames.shape), 0, 255).astype(np.uint8)
    graph = BranchGraph.from_edges(0, bv.edges)
    # node patches here are discs, not a thin stem: the branch-band mask does not apply
    res = LKTracker(LKConfig(mask_to_branch=False)).track(ArraySource(frames), bv.true_xy[:, 0], graph)
    err = np.hypot(*(res.xy - bv.true_xy).transpose(2, 0, 1))
    return bv, frames, graph, res, err


def test_accuracy_on_visible_frames(scene):
    bv, _, _, res, err = scene
    assert res.xy.shape == bv.true_xy.shape
    ok = res.visible & ~bv.occluded
    assert np.median(err[ok]) < 0.3
    assert np.percentile(err[ok], 90) < 1.0
    # the scene really moves: the tip sweeps tens of pixels
    assert np.ptp(bv.true_xy[-1, :, 0]) > 30


def test_no_drift_returns_to_first_pose(scene):
    bv, _, _, res, err = scene
    np.testing.assert_allclose(bv.true_xy[:, -1], bv.true_xy[:, 0], atol=1e-6)  # the clip closes its loop
    assert res.visible[:, -1].all()
    assert err[:, -1].max() < 1.0


def test_occluded_nodes_marked_invisible_and_recovered(scene):
    bv, frames, graph, res, err = scene
    assert bv.occluded.sum() > 20
    # without the frame-to-frame hold, a node under the leaf is marked invisible
    strict = LKTracker(LKConfig(mask_to_branch=False, hold=False)).track(ArraySource(frames), bv.true_xy[:, 0], graph)
    assert (~strict.visible & bv.occluded).sum() >= 0.8 * bv.occluded.sum()
    # with it (the default) a covered node is either invisible or held near where it is, with a grown sigma
    held = res.visible & bv.occluded
    assert (err[held] < 2.5).all()
    assert (res.sigma_px[held] > np.median(res.sigma_px[res.visible])).all()
    # after the leaf has passed every node is found again, accurately
    last_occ = np.flatnonzero(bv.occluded.any(axis=0)).max()
    after = slice(last_occ + 5, None)
    assert res.visible[:, after].mean() > 0.95
    assert np.median(err[:, after][res.visible[:, after]]) < 0.3
    # an invisible entry still has a finite position and a large sigma
    assert np.isfinite(res.xy).all()
    assert (res.sigma_px[~res.visible] > res.sigma_px[res.visible].max()).all()


def test_sigma_is_calibrated_to_a_factor_of_two(scene):
    bv, _, _, res, _ = scene
    ok = res.visible & ~bv.occluded
    z = (res.xy - bv.true_xy)[ok] / res.sigma_px[ok][:, None]
    assert 0.5 < z.std() < 2.0


def test_table_round_trips_through_tracks_loader(scene, tmp_path):
    from rce_gtsam.tracks import load_tracks

    _, _, graph, res, _ = scene
    path = res.write_csv(tmp_path / "t.csv")
    tracks = load_tracks(path, graph)
    np.testing.assert_allclose(tracks.observed, res.visible)
    np.testing.assert_allclose(tracks.xy[res.visible], res.xy[res.visible], atol=1e-4)


def test_works_without_graph_and_honours_max_frames(scene):
    bv, frames, _, _, _ = scene
    res = LKTracker().track(ArraySource(frames[:60]), bv.true_xy[:, 0], None, max_frames=40)
    assert res.n_frames == 40
    err = np.hypot(*(res.xy - bv.true_xy[:, :40]).transpose(2, 0, 1))
    assert np.median(err[res.visible]) < 0.3


def test_bad_inputs(scene):
    bv, frames, _, _, _ = scene
    with pytest.raises(InputError, match="outside"):
        LKTracker().track(ArraySource(frames[:2]), [[1000.0, 5.0]])
    g = BranchGraph.from_edges(0, [[0, 1], [1, 99]])
    with pytest.raises(InputError, match="node 99"):
        LKTracker().track(ArraySource(frames[:2]), bv.true_xy[:2, 0], g)
    # a later frame that is not RGB (the grey conversion runs in the decode thread): one line, not a cv2 error
    mixed = [frames[0], frames[1], frames[2][..., 0]]
    with pytest.raises(InputError, match="frame 2 is not an RGB image"):
        LKTracker().track(ArraySource(mixed), bv.true_xy[:, 0], BranchGraph.from_edges(0, bv.edges))


def test_default_tracker_on_simulator_render(tmp_path):
    """The simulator's rendered video (thin textured stem, fluttering leaves, H.264): default config."""
    from rce_gtsam.sim.simulate import SimulationConfig
    from rce_gtsam.track import open_video

    sim, video, truth = rendered_simulation(tmp_path, SimulationConfig(n_nodes=12, n_frames=150, seed=1))
    with open_video(video) as src:
        res = LKTracker().track(src, truth[:, 0], sim.graph)
    err = np.hypot(*(res.xy - truth).transpose(2, 0, 1))
    assert np.median(err[res.visible]) < 1.0
    assert res.visible.mean() > 0.8
    assert np.median(err[:, -1][res.visible[:, -1]]) < 1.0


def test_distinct_reacquire_keeps_a_lost_node_off_its_twin():
    """A self-similar stem repeats its knots: a lost node must not lock onto a neighbouring knot.

    A periodic stem of identical 14-px knots; the tracked knot A is covered in frame 1 (lost), then
    reappears slightly degraded, so its neighbours 14 px away (inside the re-acquisition window)
    correlate about as well as A itself. With ``distinct_reacquire`` the tracker must mark A invisible while the match is ambiguous,
    never visible on a neighbouring knot.
    """
    rng = np.random.default_rng(3)
    knot = rng.uniform(40, 215, (15, 14))
    base = np.full((120, 160), 128.0)
    base[53:68, 22:92] = np.tile(knot, (1, 5))  # knots centred at x = 29, 43, 57, 71, 85; A = (57, 60)
    frames = []
    for f in range(20):
        img = base.copy()
        if f == 1:
            img[50:71, 47:68] = 128.0  # A covered
        elif f >= 2:
            img[53:68, 50:64] = knot + rng.normal(0, 10, knot.shape)  # A back, degraded
        img += rng.normal(0, 2, img.shape)
        frames.append(np.repeat(np.clip(img, 0, 255).astype(np.uint8)[..., None], 3, axis=2))
    res = LKTracker(LKConfig(distinct_reacquire=True)).track(ArraySource(np.stack(frames)), [[57.0, 60.0]])
    err = np.hypot(res.xy[0, :, 0] - 57.0, res.xy[0, :, 1] - 60.0)
    assert not res.visible[0, 1]                        # covered: invisible
    assert (err[res.visible[0]] < 2.0).all()            # never visible on a neighbouring knot
    assert res.info["rejected_ambiguous"] > 0


def test_colour_mask_keeps_bark_and_drops_a_leaf():
    """The branch-colour mask keeps the stem (dark knots included) and drops a green leaf and the background."""
    rng = np.random.default_rng(0)
    img = np.empty((80, 120, 3))
    img[:] = (110, 125, 105)                                    # grey-green background
    img[36:45, 10:110] = (150, 95, 60)                          # brown stem along y = 40
    img[36:45, 50:54] = (75, 48, 30)                            # a dark knot: same hue, half the brightness
    img[30:44, 80:92] = (60, 170, 50)                           # a green leaf over the stem
    img = np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8)
    q = np.array([[15.0, 40.0], [60.0, 40.0], [105.0, 40.0]])
    graph = BranchGraph.from_edges(0, [[0, 1], [1, 2]])
    fg = LKTracker._branch_colour_mask(img, q, graph)
    assert fg[38:43, 15:45].mean() > 0.95      # bark
    assert fg[38:43, 50:54].mean() > 0.9       # dark knot (noisier chromaticity: fewer photons)
    assert fg[38:43, 82:90].mean() < 0.05      # leaf in front of the stem
    assert fg[5:25, :].mean() < 0.05           # background


def test_lost_node_is_not_reacquired_while_its_parent_is_lost():
    """A node re-found while its parent is still lost has no graph check on it (simulator seed 0: a tip
    re-found 18 px off beside a leaf, then followed to 67 px while marked visible). It is not re-anchored: it is
    reported with a widened sigma (``LKConfig.soft_reject``, ``HOW`` 4: such matches were right to a median of
    1.1 px on plant 2), and re-anchored tightly once the parent is seen again. With ``soft_reject`` off it stays
    invisible until then."""
    bv = branch_video(n_frames=16, size=(200, 200), n_nodes=5, tip_amp_px=0.0, gust_amp_px=0.0, occluder=False,
                      seed=4)
    frames = bv.frames.astype(float)
    rng = np.random.default_rng(1)
    cover = {3: range(2, 10), 4: range(2, 6)}  # node 4 (the tip) comes back at frame 6, its parent at 10
    for node, span in cover.items():
        x, y = np.round(bv.true_xy[node, 0]).astype(int)
        for f in span:
            frames[f, y - 8:y + 9, x - 8:x + 9] = 90.0
    frames = np.clip(frames + rng.normal(0, 2, frames.shape), 0, 255).astype(np.uint8)
    graph = BranchGraph.from_edges(0, bv.edges)
    res = LKTracker(LKConfig(mask_to_branch=False)).track(ArraySource(frames), bv.true_xy[:, 0], graph)
    err = np.hypot(*(res.xy - bv.true_xy).transpose(2, 0, 1))
    assert not res.visible[3, 2:10].any() and not res.visible[4, 2:6].any()
    assert res.info["rejected_unanchored"] > 0
    # the tip, back at frame 6 while its parent is covered: right, but not trusted as an anchored match
    assert res.visible[4, 6:10].all() and (res.info["how"][4, 6:10] == 4).all()
    assert (res.sigma_px[4, 6:10] >= 1.0).all() and (err[4, 6:10] < 0.5).all()
    assert res.visible[3:, 11:].all() and (err[3:, 11:] < 0.5).all()  # both found again afterwards
    assert (res.sigma_px[3:, 11:] < 0.5).all()
    strict = LKTracker(LKConfig(mask_to_branch=False, soft_reject=False)).track(ArraySource(frames), bv.true_xy[:, 0],
                                                                                graph)
    assert not strict.visible[4, 2:10].any()  # tip waits for its parent


def _track_simulator_render(tmp_path, config):
    """Render ``simulate(config)`` to H.264 and track it with the default tracker from the true first-frame
    positions: (simulation, video path, TrackResult, (N, F) error in px against the true positions)."""
    sim, video, truth = rendered_simulation(tmp_path, config)
    return (sim, video, *_track_video(sim, video, truth))


def _track_video(sim, video, truth):
    from rce_gtsam.track import open_video

    with open_video(video) as src:
        res = LKTracker().track(src, truth[:, 0], sim.graph)
    return res, np.hypot(*(res.xy - truth).transpose(2, 0, 1))


def test_tip_is_not_visible_beside_the_stem_on_simulator_seed0(tmp_path, monkeypatch):
    """Regression (simulator seed 0, 150 frames, 12 nodes, clean H.264 render): the tip (node 11) swings
    ~35 degrees further than its parent segment and is lost; re-acquired in the wide window with its
    template rotated by the parent's rotation, it used to be reported VISIBLE 10.6 px off, on the background
    beside the stem (frames 109-115: correlation 0.53, distinct, forward-backward 0.4 px, length plausible).
    Re-matched with the rotation that position implies (the refinement pass) it scores 0.44-0.46 < min_ncc:
    the match is not self-consistent, and is now marked invisible. A visible point that far off is fake
    bending downstream. Measured: max error of visible points 10.6 -> 0.7 px, visible 0.957 -> 0.957.
    Since tips are matched with their branch band (``_TIP_MIN_BAND_PX``) the tip is no longer re-acquired
    beside the stem on this clip at all (max error 0.78 px, visible 0.976, tip visible 0.71, no refinement
    rejection), so the check itself is exercised with the full-patch tip template it was made for."""
    from rce_gtsam.sim.simulate import SimulationConfig

    sim, video, res, err = _track_simulator_render(tmp_path, SimulationConfig(n_nodes=12, n_frames=150, seed=0))
    assert err[res.visible].max() < 3.0
    assert res.visible.mean() > 0.94
    assert res.visible[11].mean() > 0.4  # the tip is still followed where it can be (0.51 -> 0.49 -> 0.71)

    from rce_gtsam.track import lk_frame0

    monkeypatch.setattr(lk_frame0, "_TIP_MIN_BAND_PX", math.inf)  # the tip matched with its full patch
    res, err = _track_video(sim, video, truth_by_node_id(sim))
    assert err[res.visible].max() < 3.0
    assert res.visible[11].mean() > 0.4
    assert res.info["rejected_refine"] > 0


def test_tip_is_matched_with_its_branch_band_on_simulator_seed2(tmp_path):
    """Regression (simulator seed 2, 40 frames, 20 nodes, clean H.264 render): a tip's branch band holds fewer
    than 4 (2h + 1) pixels (one segment, the thinnest stem: 28 here), so it used to be matched with its full
    patch, which is mostly static background; the match was pinned toward the frame-0 surroundings and the
    tip was reported visible up to 2.8 px off (18 frames > 1 px). It is now matched with its band (down to
    16 pixels): max error of the visible tip 0.86 px. On the 600-frame clip of this seed the visible tip's max
    error went 14.1 -> 0.74 px (71 -> 0 frames > 2 px, visible 0.55 -> 0.30); Spearman of kappa unchanged
    there (0.903), and on seed 3 0.674 -> 0.765."""
    from rce_gtsam.sim.simulate import SimulationConfig

    sim, _, res, err = _track_simulator_render(tmp_path, SimulationConfig(n_frames=40, seed=2))
    tip = 19
    assert sim.graph.parent[tip] == 18 and not sim.graph.children.get(tip)
    assert res.visible[tip].mean() > 0.4            # measured 0.62 (old: 0.85, but off)
    assert err[tip][res.visible[tip]].max() < 1.5   # measured 0.86 px (old: 2.76 px)


def test_refinement_thread_gives_bit_identical_tracks(tmp_path):
    """``LKConfig.threads=2`` (the refinement pass in a second thread, node by node behind the first pass) reads
    exactly what the sequential passes read: same positions, visibility, sigma and counts to the bit, whatever
    the threads' timing (simulator seed 3, 20 nodes, 30 frames of the H.264 render; tracked twice threaded).
    A node re-matched before its child's first-pass match or its parent's re-match would differ here."""
    simulate = pytest.importorskip("rce_gtsam.sim.simulate")
    render = pytest.importorskip("rce_gtsam.sim.render")
    from rce_gtsam.track import open_video

    sim = simulate.simulate(simulate.SimulationConfig(n_nodes=20, n_frames=30, seed=3))
    with open_video(render.render_video(sim, tmp_path / "v.mp4")) as src:
        frames = np.stack([fr.image for fr in src])
    q0 = truth_by_node_id(sim)[:, 0]
    runs = [LKTracker(LKConfig(threads=t)).track(ArraySource(frames), q0, sim.graph) for t in (1, 2, 2)]
    assert runs[0].info["anchored"] > 0
    for r in runs[1:]:
        for name in ("xy", "visible", "sigma_px"):
            np.testing.assert_array_equal(getattr(r, name), getattr(runs[0], name))
        np.testing.assert_array_equal(r.info["how"], runs[0].info["how"])
        assert {k: v for k, v in r.info.items() if k not in ("time_total_s", "how")} == \
            {k: v for k, v in runs[0].info.items() if k not in ("time_total_s", "how")}
    with pytest.raises(InputError, match="threads must be 1 or 2"):
        LKConfig(threads=3)
