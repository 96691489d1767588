"""The default tracker's bridge step (``rce_gtsam.track.lk_bridge``): a lost node between a seen ancestor and a seen
descendant is re-found from the two, with a real tracker's frame-0 set-up on a rendered branch."""

from __future__ import annotations

import cv2
import numpy as np

from rce_gtsam.graph import BranchGraph
from rce_gtsam.track import ArraySource, LKTracker

from track_fixtures import branch_video


def _setup(frame: int):
    bv = branch_video(n_frames=41, size=(240, 200), n_nodes=7, tip_amp_px=100.0, gust_amp_px=0.0, occluder=False,
                      period_frames=40, seed=3)
    graph = BranchGraph.from_edges(0, bv.edges)
    t = LKTracker()
    t.track(ArraySource(bv.frames[:2]), bv.true_xy[:, 0], graph)  # frame-0 set-up (templates, bands)
    grey = [cv2.cvtColor(bv.frames[f], cv2.COLOR_RGB2GRAY) for f in (0, frame)]
    return t, bv, grey


def _bridge(t, grey, q0, est, vis):
    n = len(est)
    sig, how = np.full(n, 0.1), np.where(vis, 0, -1).astype(np.int8)
    counts = {"bridged": 0}
    t._bridge(grey[0], grey[1], q0, est, vis, sig, how, np.zeros(n, int), counts, 1.0, 0.5 * t.h)
    return sig, how, counts


def test_a_lost_node_between_seen_neighbours_is_refound_where_it_is():
    f = 10  # a quarter period: the branch is far from its frame-0 pose
    t, bv, grey = _setup(f)
    truth = bv.true_xy[:, f]
    assert np.hypot(*(truth[5] - bv.true_xy[5, 0])) > 2 * t.h  # moved beyond the wide search
    est, vis = truth.copy(), np.ones(len(truth), bool)
    est[5] = bv.true_xy[5, 0]  # lost: left at its frame-0 position
    vis[5] = False
    sig, how, counts = _bridge(t, grey, bv.true_xy[:, 0], est, vis)
    assert vis[5] and how[5] == 5 and counts["bridged"] == 1
    assert np.hypot(*(est[5] - truth[5])) < 1.0 and 1.0 <= sig[5] < 1.5
    # two lost nodes in a row (4 and 5, between 3 and the tip 6): both re-found
    est, vis = truth.copy(), np.ones(len(truth), bool)
    est[4:6], vis[4:6] = bv.true_xy[4:6, 0], False
    _, how, counts = _bridge(t, grey, bv.true_xy[:, 0], est, vis)
    assert vis[4:6].all() and counts["bridged"] == 2 and (np.hypot(*(est[4:6] - truth[4:6]).T) < 1.0).all()
    # no seen descendant (every node below 4 lost too): nothing to bridge from
    est, vis = truth.copy(), np.ones(len(truth), bool)
    vis[4:] = False
    _, how, counts = _bridge(t, grey, bv.true_xy[:, 0], est, vis)
    assert not vis[4:].any() and counts["bridged"] == 0


def test_no_bridge_from_a_descendant_that_is_not_where_the_branch_is():
    f = 10
    t, bv, grey = _setup(f)
    truth = bv.true_xy[:, f]
    est, vis = truth.copy(), np.ones(len(truth), bool)
    vis[5] = False
    est[5] = truth[5] + 20.0
    est[6] = truth[4] + 2.0 * (truth[6] - truth[4])  # the span 4-6 stretched to twice its length
    _, how, counts = _bridge(t, grey, bv.true_xy[:, 0], est, vis)
    assert not vis[5] and counts["bridged"] == 0
