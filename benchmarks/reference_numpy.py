"""The published computation as one plain numpy/scipy process: the speed floor `rce analyze` is compared with.

Usage: python benchmarks/reference_numpy.py TRACKS.csv GRAPH.json [--boot 250] [--seed 0]

Standalone on purpose (imports numpy and scipy only, nothing of rce_gtsam), following
shared/docs/reference-pipeline.md: moving average 5 over each node's observed samples (edge padding) ->
the four-term quadratic smoother (measurement 1.0, first difference 0.35, second difference 0.2, frame-0
edge offset vector 0.45) as one sparse linear least-squares problem per axis, solved exactly through a
sparse LU of its normal equations (both axes share the matrix) -> rest lengths and root distances ->
unsigned interior angles and their change from the first common frame -> per-bend MAD mask (3.5) ->
rank-1 ALS on |delta| (lambda 12, 60 iterations, geometric-mean normalisation) -> 250 moving-block
bootstrap refits (blocks of 25 frames, seed 0) with percentile 95 % intervals. Prints kappa [CI] per edge
and the process wall time (from the interpreter's start, imports included).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

EPS = 1e-6


def process_seconds() -> float:
    """Wall seconds since this process started (Linux /proc; else since this module ran)."""
    try:
        with open("/proc/self/stat") as f:
            start = float(f.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
        with open("/proc/uptime") as f:
            return float(f.read().split()[0]) - start
    except (OSError, ValueError, IndexError):
        return time.perf_counter()


def load(tracks_csv, graph_json):
    g = json.load(open(graph_json))
    root, edges = int(g["root"]), [(int(a), int(b)) for a, b in g["edges"]]
    parent = {b: a for a, b in edges}
    order, children = [root], {}
    for a, b in edges:
        children.setdefault(a, []).append(b)
    for n in order:  # breadth-first
        order.extend(children.get(n, []))
    data = np.loadtxt(tracks_csv, delimiter=",", skiprows=1)
    row = {n: i for i, n in enumerate(order)}
    keep = np.isin(data[:, 0].astype(int), order)
    data = data[keep]
    F = int(data[:, 1].max()) + 1
    xy = np.full((len(order), F, 2), np.nan)
    xy[[row[int(p)] for p in data[:, 0]], data[:, 1].astype(int)] = data[:, 2:4]
    return root, edges, parent, children, order, row, xy


def moving_average(xy, window=5):
    out = np.full_like(xy, np.nan)
    h = window // 2
    for i in range(xy.shape[0]):
        ok = np.isfinite(xy[i, :, 0])
        v = xy[i, ok]
        pad = np.concatenate([np.repeat(v[:1], h, 0), v, np.repeat(v[-1:], h, 0)])
        k = np.ones(window) / window
        out[i, ok] = np.stack([np.convolve(pad[:, a], k, mode="valid") for a in (0, 1)], axis=1)
    return out


def smooth(ma, edges, row, w_m=1.0, w_v=0.35, w_a=0.2, w_e=0.45):
    N, F, _ = ma.shape
    col = lambda i, t: i * F + t  # noqa: E731
    rows, cols, vals, rhs = [], [], [], []
    r = 0

    def add(entries, b, w):
        nonlocal r
        s = np.sqrt(w)
        for c, v in entries:
            rows.append(r), cols.append(c), vals.append(s * v)
        rhs.append(s * np.asarray(b, float))
        r += 1
    for i in range(N):
        for t in np.flatnonzero(np.isfinite(ma[i, :, 0])):
            add([(col(i, t), 1.0)], ma[i, t], max(w_m, 1e-9))
        for t in range(F - 1):
            add([(col(i, t), -1.0), (col(i, t + 1), 1.0)], (0, 0), w_v)
        for t in range(1, F - 1):
            add([(col(i, t - 1), 1.0), (col(i, t), -2.0), (col(i, t + 1), 1.0)], (0, 0), w_a)
    for a, b in edges:
        both = np.isfinite(ma[row[a], :, 0]) & np.isfinite(ma[row[b], :, 0])
        t0 = int(np.flatnonzero(both)[0])
        d = ma[row[b], t0] - ma[row[a], t0]
        for t in range(F):
            add([(col(row[b], t), 1.0), (col(row[a], t), -1.0)], d, w_e)
    A = sp.csr_matrix((vals, (rows, cols)), shape=(r, N * F))
    B = np.array(rhs)
    lu = spla.splu((A.T @ A).tocsc())
    p = lu.solve(A.T @ B)
    out = p.reshape(N, F, 2)
    out[~np.isfinite(ma[:, :, 0])] = np.nan  # written back at observed frames only
    return out


def bends_of(root, parent, children):
    return [(parent[j], j, c) for j in children if j != root for c in children[j]]


def angles(xy, row, bends):
    out = np.full((len(bends), xy.shape[1]), np.nan)
    for k, (g, j, c) in enumerate(bends):
        u, v = xy[row[g]] - xy[row[j]], xy[row[c]] - xy[row[j]]
        nu, nv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos = np.clip(np.sum(u * v, axis=1) / (nu * nv), -1, 1)
        th = np.degrees(np.arccos(cos))
        th[(nu < 1e-12) | (nv < 1e-12)] = np.nan
        ok = np.flatnonzero(np.isfinite(th))
        out[k] = th - th[ok[0]]
    return out


def mad_inliers(delta, thr=3.5):
    inl = np.zeros(delta.shape, bool)
    for k, d in enumerate(delta):
        ok = np.isfinite(d)
        med = np.median(d[ok])
        mad = np.median(np.abs(d[ok] - med))
        if ok.sum() < 3 or mad <= 1e-9:
            inl[k] = ok
        else:
            with np.errstate(invalid="ignore"):
                inl[k] = ok & (0.6745 * np.abs(d - med) / mad <= thr)
    return inl


def fit_rank1(Y, W, lam=12.0, n_iter=60):
    Y0 = np.where(W, Y, 0.0)
    with np.errstate(invalid="ignore"):
        z = np.nanmedian(np.where(W, Y, np.nan), axis=0)
    z = np.nan_to_num(z)
    if z.max() <= 1e-9:
        z = np.ones(Y.shape[1])
    kappa = np.ones(Y.shape[0])
    for _ in range(n_iter):
        prev = kappa
        S = W & (z > EPS)[None]
        n = S.sum(1)
        k_hat = np.maximum((S * z * Y0).sum(1) / np.maximum((S * z**2).sum(1), EPS), EPS)
        kappa = np.where(n > 0, np.exp(n / (n + lam) * np.log(k_hat)), 1.0)
        big = kappa > EPS
        kappa = np.where(big, kappa / np.exp(np.mean(np.log(kappa[big]))), kappa)
        K = W & big[:, None]
        z = np.maximum(0.0, (K * kappa[:, None] * Y0).sum(0) / np.maximum((K * kappa[:, None] ** 2).sum(0), EPS))
        if np.max(np.abs(np.log(np.maximum(kappa, EPS) / np.maximum(prev, EPS)))) < 1e-4:
            break
    return kappa


def bootstrap(Y, W, n_boot=250, block=25, seed=0):
    T = Y.shape[1]
    L = max(3, min(block, T))
    rng = np.random.default_rng(seed)
    ks = []
    for _ in range(n_boot):
        idx = []
        while len(idx) < T:
            s = int(rng.integers(0, T - L + 1))
            idx.extend(range(s, s + L))
        idx = np.array(idx[:T])
        ks.append(fit_rank1(Y[:, idx], W[:, idx]))
    return np.percentile(np.array(ks), [2.5, 97.5], axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tracks")
    ap.add_argument("graph")
    ap.add_argument("--boot", type=int, default=250)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    root, edges, parent, children, order, row, xy = load(args.tracks, args.graph)
    sm = smooth(moving_average(xy), edges, row)
    rest = {(a, b): None for a, b in edges}
    for a, b in edges:
        both = np.flatnonzero(np.isfinite(sm[row[a], :, 0]) & np.isfinite(sm[row[b], :, 0]))
        rest[(a, b)] = float(np.linalg.norm(sm[row[b], both[0]] - sm[row[a], both[0]]))
    dist = {root: 0.0}
    for n in order[1:]:
        dist[n] = dist[parent[n]] + rest[(parent[n], n)]
    bends = bends_of(root, parent, children)
    bends.sort(key=lambda b: (dist[b[2]], b[1], b[2]))  # rows by root distance, then joint, then child
    delta = angles(sm, row, bends)
    W = mad_inliers(delta) & np.isfinite(delta)
    frames = np.flatnonzero(np.isfinite(delta).any(0))
    Y, W = np.abs(np.nan_to_num(delta[:, frames])), W[:, frames]
    kappa = fit_rank1(Y, W)
    lo, hi = bootstrap(Y, W, args.boot, seed=args.seed)
    for (g, j, c), k, a, b in zip(bends, kappa, lo, hi):
        print(f"{j:>4}->{c:<4} kappa {k:.3f} [{a:.3f}, {b:.3f}]")
    print(f"reference total {process_seconds():.2f} s wall (process start to here)")


if __name__ == "__main__":
    main()
