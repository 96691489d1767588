"""The swing's signature in the segments' lengths: neighbouring segments' loadings on the shared course agree.

The length channel's test (:mod:`~rce_gtsam.diagnosis.length_channel`) asks whether segments that share no tracked
node keep a course in common. A swing out of the image plane gives them one, but so does a tracker error whose
*time course* the nodes share while each node takes its own part of it: frame-wide compression or lighting
changes, or motion that every node's error follows. On real texture with known planar motion (the texture bed,
H.264 at crf 23) the length test fired at p <= 0.01 on 4 of 10 recordings, and on the user's path (``rce simulate
--video``, our tracker) on 2 of 20 effect-free renders (record ``swing_signature``; 8 of 120 on earlier seeds).
What tells the two apart is how the course loads along the branch.

**Physics.** A segment's elevation out of the branch plane adds up from the root, chi_e(t) = sum over the joints
from the root to e of kappa_o_j z_o(t), so neighbouring segments swing together and their length changes
(-tan(alpha_e) chi_e in a tilted plane, -chi_e^2 / 2 in the image plane) load on the shared course with the same
sign and a similar size. A node's error enters the two segments that meet at it with opposite signs (+1 on the
segment it ends, -1 on the one it starts), so a course the nodes share with a part of their own gives neighbouring
segments loadings that disagree: with independent node parts, a correlation of about -1/2.

**Statistic.** The agreement of neighbouring segments' loadings l_e on the course the length test found (the one
its two node-disjoint sets share, :func:`~rce_gtsam.diagnosis.length_channel.shared_course`): A = sum over
(parent segment, child segment) pairs of l_a l_b / sum over segments of l_e^2 (about +1 for a swing, about -1/2
for node parts, 0 for loadings unrelated along the branch).
**Null:** the loadings are differences of independent, sign-symmetric node parts. The node parts are recovered by
adding the loadings up from the root (the root's part 0; any loading vector on a tree is such a difference), each
node's part gets a random sign (``N_FLIPS`` draws, seeded), and A is recomputed: exact under the null, and a swing,
whose parts grow steadily from the root, loses its agreement under the flips. p one-sided,
(1 + #{A_flip >= A}) / (1 + n). **Level:** ``ALPHA_AGREE``. Naming ``out_of_plane`` needs both this and the length
test (an intersection-union rule: the length test guards against a node's own error in time, this one against a
course the nodes share with parts of their own).

**Calibration** (``benchmarks/bench_swing_signature.py``, record ``swing_signature``): how often both tests fire on
planar recordings (the simulator's tracker-artifact families, the user's path, the texture bed) and on swings (the
simulator, the user's path). Units: none (a ratio of sums of squared loadings).
"""

from __future__ import annotations

import numpy as np

#: sign-flip draws of the null (p resolution 1/1000)
N_FLIPS = 999
#: the agreement test's level: the length test's own (ALPHA_OOP). Both must hold to name a swing, so a course the
#: nodes share with parts of their own (where the length test holds by construction) is named at most this often.
ALPHA_AGREE = 0.01
#: fewer (parent, child) pairs of segments with loadings than this: no test (p = 1: no signature can be seen)
MIN_PAIRS = 4

def node_parts(segments, loadings: np.ndarray) -> tuple[list, np.ndarray]:
    """(nodes, parts): each node's part of the loadings, added up along ``segments`` [(parent, child)] from the
    root(s), whose part is 0; a NaN loading counts 0 (its child keeps its parent's part)."""
    load = np.nan_to_num(np.asarray(loadings, float))
    segs = [(int(p), int(c)) for p, c in segments]
    part = {n: 0.0 for n in {p for p, _ in segs} - {c for _, c in segs}}
    todo = list(range(len(segs)))
    while todo:
        later = [i for i in todo if segs[i][0] not in part]
        for i in todo:
            if segs[i][0] in part:
                part[segs[i][1]] = part[segs[i][0]] + load[i]
        if len(later) == len(todo):  # a cycle or a segment hanging from nowhere: its nodes start from 0
            part.update({segs[i][0]: 0.0 for i in later})
        todo = later
    nodes = sorted(part)
    return nodes, np.array([part[n] for n in nodes])


def agreement(segments, loadings: np.ndarray, seed: int = 0, n_flips: int = N_FLIPS) -> tuple[float, float]:
    """(A, one-sided sign-flip p) of the neighbouring segments' loadings (module docstring); ``segments``
    [(parent, child)], ``loadings`` (S,), NaN = left out. (A, 1) where fewer than ``MIN_PAIRS`` pairs have loadings
    (A 0 without any)."""
    load = np.asarray(loadings, float)
    ok = np.isfinite(load)
    segs = [(int(p), int(c)) for p, c in segments]
    ending_at = {c: i for i, (_, c) in enumerate(segs)}
    pairs = np.array([(ending_at[p], i) for i, (p, _) in enumerate(segs) if p in ending_at
                      and ok[ending_at[p]] and ok[i]], int).reshape(-1, 2)

    def stat(L):
        return np.sum(L[..., pairs[:, 0]] * L[..., pairs[:, 1]], axis=-1) / np.maximum(
            np.sum(np.where(ok, L, 0.0) ** 2, axis=-1), 1e-300)

    a = float(stat(np.where(ok, load, 0.0))) if len(pairs) else 0.0
    if len(pairs) < MIN_PAIRS:
        return a, 1.0
    nodes, parts = node_parts(segs, load)
    row = {n: k for k, n in enumerate(nodes)}
    P, C = np.array([row[p] for p, _ in segs]), np.array([row[c] for _, c in segs])
    signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=(n_flips, len(nodes)))
    flipped = signs[:, C] * parts[C] - signs[:, P] * parts[P]
    return a, float((1 + np.sum(stat(flipped) >= a - 1e-12)) / (1 + n_flips))


def rank_growth(root_distance: np.ndarray, loadings: np.ndarray) -> float:
    """Spearman's rho of |loadings| against ``root_distance`` (NaN loadings left out; ties share their mean rank):
    a swing's loadings grow toward the tip. Descriptive (the report quotes it); 0 with fewer than 3 loadings or no
    spread."""
    load = np.asarray(loadings, float)
    ok = np.isfinite(load)
    if ok.sum() < 3:
        return 0.0
    d, a = _ranks(np.asarray(root_distance, float)[ok]), _ranks(np.abs(load[ok]))
    if np.std(d) == 0 or np.std(a) == 0:
        return 0.0
    return float(np.corrcoef(d, a)[0, 1])


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks of a 1-D array from 0, ties sharing their mean rank."""
    _, inverse, counts = np.unique(x, return_inverse=True, return_counts=True)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return (first + (counts - 1) / 2.0)[inverse]
