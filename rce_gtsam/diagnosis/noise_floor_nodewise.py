"""The angle-noise floor from the tracker's node-wise signature: how much of the rank-1 residual is node error?

A tracker's error belongs to a node. A node's error across the branch, n_i (px), turns the three bends it takes
part in by the pattern of :mod:`.noise_floor`'s first equation,

    d theta_j = n_c / L2 - n_j (1 / L1 + 1 / L2) + n_g / L1        (radians),

so two bends that share a node share its error, with a sign and size fixed by the geometry: with independent
node errors of variance s2 (px^2) the angle-noise covariance is s2 A A' (A: bends x nodes, deg per px), negative
between neighbouring bends (-4 s2 / L^2 against a variance of 6 s2 / L^2 on an even chain). The rank-1 fit
takes out, frame by frame, the part of the noise along kappa (P = I - k k' / k'k), so its residual's covariance
is s2 P A A' P plus whatever the model misses. The covariances between bends that share a node give s2 by least
squares; a bend's floor is s2 (A A')_jj.

Why it is needed beside the inextensibility estimate: that one carries the along-stem error, seen in the
segments' stretch, across the branch with the across/along ratio of the fast jitter. A tracker's *slow* error
(drift) is about as large across as along, so there it reads 0.4-0.6 of the truth
(``benchmarks/bench_artifacts.py``, drift family); this estimate needs no ratio and sees every frequency.
What it assumes: node errors independent between nodes (the tracker follows each node on its own), and a misfit
of the model that does not put *negative* covariance between neighbouring bends. The effects' residuals do not
(a delay, inertia, a second excitation or a saturation moves neighbouring bends together, an offset one bend):
on the simulator's effect recordings it reads 0.86-0.95 of the true noise, never above it. So it raises the
floor only where the tracker's own signature says the noise is larger than the inextensibility estimate saw.

The kappa step takes some noise too (:func:`kappa_step_absorption`): each bend's kappa is a regression on the
excitation z, so the part of the bend's noise that follows z goes into the fit. For white noise that is ~1/T of
its variance; for a slow drift under a slow excitation (both in the few lowest frequencies) it is a large part,
and the residual's covariance then reads the node error low. s2 is divided by (1 - a), a the expected share.
Measured (``benchmarks/bench_artifacts.py --floor-only``, record ``artifacts``, 40 seeds): under the drift family
at twice its measured size the floor read a median 0.74 of the true noise before (18 of 40 within 25 %), 0.84 with
it (36 of 40); the other families' medians moved by 0.01 at most, and on the simulator's effect recordings (delay,
dynamics, offset, second mode, saturation; 8 seeds each) the floor moved by 0.02 of the truth at most.

Units: px (positions, s2 in px^2), deg (angles, variances in deg^2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: fewest pairs of node-sharing bends (off-diagonal covariances) the least-squares s2 needs
MIN_PAIRS = 4


#: largest share of a frequency's noise power the kappa step is taken to remove (its share of z's power, w_k, is
#: clipped here: a frequency holding nearly all of z's power would otherwise have its residual power multiplied
#: without bound by 1 / (1 - w_k))
MAX_BIN_SHARE = 0.9
#: largest share of the noise variance the kappa step is taken to remove: the floor is at most doubled
MAX_ABSORBED = 0.5


@dataclass(frozen=True)
class NodewiseFloor:
    """The node-wise floor. variance_deg2: (E,) s2 (A A')_jj per bend (deg^2; NaN = not estimable);
    sigma_px: sqrt(s2), the node error's SD across the branch (px; NaN = not estimable); n_pairs: node-sharing
    bend pairs it rests on; absorbed: the share of the noise variance the kappa step took (s2 is corrected for
    it; 0 = not corrected)."""

    variance_deg2: np.ndarray
    sigma_px: float
    n_pairs: int
    absorbed: float = 0.0


def kappa_step_absorption(residuals: np.ndarray, z: np.ndarray) -> float:
    """Expected share a of a bend's noise variance that its own kappa takes into the rank-1 fit.

    kappa_e is the regression of bend e on the excitation z, so it takes the projection of the bend's noise n on
    z: an energy sum_k S_k |Z_k|^2 / sum_k |Z_k|^2 out of the noise's sum_t n^2 = 2 / T^2 sum_k S_k (T frames;
    k the non-zero frequencies; S_k the noise periodogram, Z_k z's Fourier transform). So
    a = (sum_k S_k w_k) / (2 sum_k S_k), w_k = |Z_k|^2 / sum_j |Z_j|^2: 1/T for white noise, a large share
    when the noise sits at z's frequencies (a slow drift under a slow excitation). S_k comes from the residuals
    (their periodograms summed over bends, :func:`~rce_gtsam.model.surrogates.pooled_periodogram`), which the
    same projection left short by about (1 - w_k): they are divided by it first (w_k clipped at
    :data:`MAX_BIN_SHARE`). Clipped to [0, :data:`MAX_ABSORBED`]; 0 when z has no power."""
    from ..model.surrogates import pooled_periodogram

    S = pooled_periodogram(residuals)[1:]
    Zp = pooled_periodogram(np.asarray(z, float)[None])[1:]  # z's own periodogram (only its shape counts: w_k)
    if S.size == 0 or not (np.isfinite(Zp).all() and Zp.sum() > 0 and np.isfinite(S).all() and S.sum() > 0):
        return 0.0
    w = Zp / Zp.sum()
    S = S / (1.0 - np.minimum(w, MAX_BIN_SHARE))
    return float(np.clip((S * w).sum() / (2.0 * S.sum()), 0.0, MAX_ABSORBED))


def angle_sensitivity(bends: list[tuple[int, int, int]], rest_xy: dict) -> np.ndarray:
    """(E, N) A: deg of bend j per px of node error across the branch, nodes in sorted order of their ids.
    bends: (grandparent, joint, child) node ids; rest_xy: {node id: (2,) rest position px}."""
    nodes = sorted({n for b in bends for n in b})
    col = {n: i for i, n in enumerate(nodes)}
    A = np.zeros((len(bends), len(nodes)))
    for j, (g, m, c) in enumerate(bends):
        L1 = float(np.linalg.norm(np.subtract(rest_xy[m], rest_xy[g])))
        L2 = float(np.linalg.norm(np.subtract(rest_xy[c], rest_xy[m])))
        if not (L1 > 0 and L2 > 0):
            return np.full((len(bends), len(nodes)), np.nan)
        A[j, col[c]] += 1.0 / L2
        A[j, col[m]] -= 1.0 / L1 + 1.0 / L2
        A[j, col[g]] += 1.0 / L1
    return np.degrees(A)


def nodewise_floor(residuals: np.ndarray, kappa: np.ndarray, bends: list[tuple[int, int, int]],
                   rest_xy: dict, z: np.ndarray | None = None) -> NodewiseFloor:
    """The node-wise floor of the rank-1 ``residuals`` (E, T deg, NaN = missing) of a fit with gains ``kappa``
    (E,: signed, kappa x direction) and excitation ``z`` (T,; None: no correction for what the kappa step took)
    on ``bends`` with rest positions ``rest_xy`` (module docstring)."""
    E = len(bends)
    none = NodewiseFloor(np.full(E, np.nan), float("nan"), 0)
    A = angle_sensitivity(bends, rest_xy)
    k = np.asarray(kappa, float)
    if not np.isfinite(A).all() or not np.isfinite(k).all() or np.linalg.norm(k) == 0:
        return none
    M = A @ A.T
    k = k / np.linalg.norm(k)
    P = np.eye(E) - np.outer(k, k)
    Mt = P @ M @ P
    ok = np.isfinite(residuals)
    means = np.nansum(residuals, axis=1, keepdims=True) / np.maximum(ok.sum(axis=1, keepdims=True), 1)
    R = residuals - means  # a row with no finite entry stays all-NaN (no warning)
    R0 = np.where(ok, R, 0.0)
    both = ok.astype(float) @ ok.T.astype(float)
    C = (R0 @ R0.T) / np.maximum(both, 1.0)
    pairs = (M != 0) & ~np.eye(E, dtype=bool) & (both >= 10)
    n_pairs = int(pairs.sum() // 2)
    if n_pairs < MIN_PAIRS or np.sum(Mt[pairs] ** 2) <= 0:
        return none
    s2 = max(float(np.sum(C[pairs] * Mt[pairs]) / np.sum(Mt[pairs] ** 2)), 0.0)
    absorbed = 0.0 if z is None else kappa_step_absorption(residuals, z)
    s2 /= 1.0 - absorbed
    return NodewiseFloor(variance_deg2=s2 * np.diag(M), sigma_px=float(np.sqrt(s2)), n_pairs=n_pairs,
                         absorbed=absorbed)
