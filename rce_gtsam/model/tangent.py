"""The rank-1 model's tangent: what a change of its gains kappa or its excitation z can absorb.

A direction G (E, T) in which some effect would move the prediction kappa_e z_t is only evidence of that effect
in the part a small change of kappa (a_e z_t) or of z (kappa_e b_t) cannot produce. The diagnosis' score tests
(:mod:`rce_gtsam.diagnosis.score_test`) and effects that prepare their test directions use it. Units: those of G.
"""

from __future__ import annotations

import numpy as np


def remove_rank1_tangent(G: np.ndarray, kappa: np.ndarray, z: np.ndarray, W: np.ndarray) -> np.ndarray:
    """G (J, E, T) minus its weighted least-squares fit by a_e z_t + kappa_e b_t (per direction): the part of
    each direction that a change of the rank-1 model's kappa (a) or excitation (b) cannot absorb. W (E, T)
    weights (0 where missing)."""
    J, E, T = G.shape
    wk = W * kappa[:, None]                      # (E, T)
    D = np.maximum(np.sum(wk * kappa[:, None], axis=0), 1e-300)  # (T,) sum_e W kappa^2
    wz = W * z[None]                              # (E, T)
    # b_t = sum_e W kappa (G - a z) / D ; normal equations for a (E x E, singular along a = c kappa):
    M = np.diag(np.sum(wz * z[None], axis=1)) - (wz * kappa[:, None]) @ (wk * z[None] / D).T
    Gk = np.einsum("et,jet->jt", wk, G) / D      # (J, T)
    r = np.einsum("et,jet->je", wz, G) - np.einsum("et,jt->je", wz * kappa[:, None], Gk)
    a = np.linalg.lstsq(M, r.T, rcond=1e-10)[0].T  # (J, E)
    b = Gk - np.einsum("et,je->jt", wk * z[None], a) / D
    return G - a[:, :, None] * z[None, None] - kappa[None, :, None] * b[:, None, :]
