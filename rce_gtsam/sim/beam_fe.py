"""Finite elements of a planar Euler–Bernoulli cantilever (Hermite cubic elements) and their time integration.

Used by :mod:`rce_gtsam.sim.beam`. Units: SI inside (metres, seconds, N, N m^2 for EI, kg/m for the mass per
length); the transverse deflection w (m) and the rotation theta = dw/dx (rad) are the two DOFs of each mesh
node. The root (mesh node 0) is clamped: its two DOFs are removed, so DOF vectors here are of length
``2 * n_elements`` (w_1, theta_1, ..., w_n, theta_n).

Element: length l, DOFs (w_a, theta_a, w_b, theta_b), cubic Hermite shape functions in xi = (x - x_a) / l:
N = [1 - 3xi^2 + 2xi^3, l(xi - 2xi^2 + xi^3), 3xi^2 - 2xi^3, l(-xi^2 + xi^3)]; curvature = N'' u_e.
EI(x) and m(x) vary along the element (evaluated at 5 Gauss points per element).

Bending law (moment M against curvature k, both relative to the rest pose; ``k_ref`` and ``beta`` of
:class:`Stiffening`): ``M = EI (k - k_c + beta k^3 / k_ref^2)`` — linear when beta = 0; beta > 0 is strain
stiffening growing with the square of the local curvature (a cubic hardening moment–curvature law, not a
corotational update: the rotations the beam reaches, a few degrees per segment, keep the small-slope strain
measure adequate; the tracked positions integrate the heading exactly, see :mod:`.beam`). ``k_c`` is a creep
eigen-curvature (a Maxwell dashpot in the weak elements): dk_c/dt = (k_g + k_mean - k_c) / tau_c, k_g the
curvature the rest load (self-weight) holds in the element, k_mean the element's mean wind curvature.

Time integration: Newmark-beta, average acceleration (gamma 1/2, beta 1/4; unconditionally stable, no numerical
damping), Rayleigh damping C = a M + b K, with Newton iterations on the residual when the law is nonlinear; the
creep state is advanced explicitly after each step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh, lu_factor, lu_solve

_GP, _GW = np.polynomial.legendre.leggauss(5)
GAUSS_XI = (_GP + 1) / 2   # Gauss points on [0, 1]
GAUSS_W = _GW / 2          # their weights (sum 1)


def hermite(xi: np.ndarray, l: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, dN/dx, d2N/dx2), each (..., 4), of the cubic Hermite element of length ``l`` at ``xi`` in [0, 1]."""
    xi, l = np.broadcast_arrays(np.asarray(xi, float), np.asarray(l, float))
    xi, l = xi[..., None], l[..., None]
    x2, x3 = xi ** 2, xi ** 3
    N = np.concatenate([1 - 3 * x2 + 2 * x3, l * (xi - 2 * x2 + x3), 3 * x2 - 2 * x3, l * (-x2 + x3)], -1)
    dN = np.concatenate([(-6 * xi + 6 * x2) / l, 1 - 4 * xi + 3 * x2, (6 * xi - 6 * x2) / l, -2 * xi + 3 * x2], -1)
    d2N = np.concatenate([(-6 + 12 * xi) / l ** 2, (-4 + 6 * xi) / l, (6 - 12 * xi) / l ** 2, (-2 + 6 * xi) / l], -1)
    return N, dN, d2N


@dataclass(frozen=True)
class Mesh:
    """A cantilever mesh. ``x`` (n_el + 1,) node positions along the beam in metres (x[0] = 0, the clamped root);
    ``EI`` and ``m`` callables of x (N m^2 and kg/m), or arrays of their values at the Gauss points (n_el, 5)."""

    x: np.ndarray
    EI_g: np.ndarray     # (n_el, 5) EI at the Gauss points, N m^2
    m_g: np.ndarray      # (n_el, 5) mass per length at the Gauss points, kg/m

    @property
    def n_el(self) -> int:
        return len(self.x) - 1

    @property
    def n_dof(self) -> int:
        return 2 * self.n_el

    @property
    def lengths(self) -> np.ndarray:
        return np.diff(self.x)

    def gauss_x(self) -> np.ndarray:
        """(n_el, 5) Gauss point positions in metres."""
        return self.x[:-1, None] + self.lengths[:, None] * GAUSS_XI[None]

    def dofs(self) -> np.ndarray:
        """(n_el, 4) global DOF index of each element DOF (-1 = the clamped root's, removed)."""
        e = np.arange(self.n_el)
        return np.stack([2 * e - 2, 2 * e - 1, 2 * e, 2 * e + 1], axis=1)

    def curvature_operator(self) -> np.ndarray:
        """(n_el, 5, 4) d2N/dx2 at each element's Gauss points: curvature = B @ u_e."""
        return hermite(GAUSS_XI[None, :], self.lengths[:, None])[2]

    def assemble(self, ke: np.ndarray) -> np.ndarray:
        """Global (n_dof, n_dof) matrix from element matrices (n_el, 4, 4); root DOFs dropped."""
        n = self.n_dof
        K = np.zeros((n + 2, n + 2))
        idx = self.dofs() + 2
        np.add.at(K, (idx[:, :, None], idx[:, None, :]), ke)
        return K[2:, 2:]

    def assemble_vec(self, fe: np.ndarray) -> np.ndarray:
        """Global (n_dof, ...) vector(s) from element vectors (n_el, 4, ...); root DOFs dropped."""
        out = np.zeros((self.n_dof + 2,) + fe.shape[2:])
        np.add.at(out, self.dofs() + 2, fe)
        return out[2:]

    def gather(self, u: np.ndarray) -> np.ndarray:
        """Element DOF values (n_el, 4, ...) of global DOF vector(s) ``u`` (n_dof, ...)."""
        full = np.concatenate([np.zeros((2,) + u.shape[1:]), u], axis=0)
        return full[self.dofs() + 2]

    def stiffness(self, factor_g: np.ndarray | None = None) -> np.ndarray:
        """K = sum of int EI (factor) B^T B dx; ``factor_g`` (n_el, 5) multiplies EI at the Gauss points."""
        B = self.curvature_operator()
        w = self.EI_g * GAUSS_W[None] * self.lengths[:, None]
        if factor_g is not None:
            w = w * factor_g
        return self.assemble(np.einsum("eg,egi,egj->eij", w, B, B))

    def mass(self, tip_mass_kg: float = 0.0) -> np.ndarray:
        """Consistent mass matrix; ``tip_mass_kg`` a point mass (fruit) on the last node's w."""
        N = hermite(GAUSS_XI[None, :], self.lengths[:, None])[0]
        w = self.m_g * GAUSS_W[None] * self.lengths[:, None]
        M = self.assemble(np.einsum("eg,egi,egj->eij", w, N, N))
        M[-2, -2] += tip_mass_kg
        return M

    def load_operator(self, lever_m: np.ndarray | None = None) -> np.ndarray:
        """(n_dof, n_el * 5) consistent load operator: f = P @ q for a distributed force q (N/m) given at the Gauss
        points (flattened element-major). ``lever_m`` (n_el, 5): lever arm (m) of the force about the beam axis
        (leaves on petioles): the force then also applies a distributed moment lever * q (N m/m)."""
        N, dN, _ = hermite(GAUSS_XI[None, :], self.lengths[:, None])
        shape = N if lever_m is None else N + lever_m[..., None] * dN
        w = (GAUSS_W[None] * self.lengths[:, None])[..., None] * shape   # (n_el, 5, 4)
        n_g = self.n_el * 5
        fe = np.zeros((self.n_el, 4, n_g))
        for e in range(self.n_el):
            fe[e, :, e * 5:(e + 1) * 5] = w[e].T
        return self.assemble_vec(fe)

    def eigen_curvature_load(self, elements: np.ndarray) -> np.ndarray:
        """(n_dof, len(elements)) equivalent nodal load of a unit eigen-curvature (creep) in each element."""
        B = self.curvature_operator()
        out = np.zeros((self.n_dof, len(elements)))
        for j, e in enumerate(elements):
            fe = np.zeros((self.n_el, 4))
            fe[e] = np.einsum("g,gi->i", self.EI_g[e] * GAUSS_W * self.lengths[e], B[e])
            out[:, j] = self.assemble_vec(fe)
        return out

    def mean_curvature(self, elements: np.ndarray) -> np.ndarray:
        """(len(elements), n_dof): an element's mean curvature (its end rotations' difference over its length)."""
        out = np.zeros((len(elements), self.n_dof + 2))
        for j, e in enumerate(elements):
            out[j, 2 * e + 1] -= 1.0 / self.lengths[e]
            out[j, 2 * e + 3] += 1.0 / self.lengths[e]
        return out[:, 2:]


def natural_frequencies_hz(K: np.ndarray, M: np.ndarray, n: int = 3) -> np.ndarray:
    """The ``n`` lowest natural frequencies (Hz) of the undamped system."""
    w2 = eigh(K, M, eigvals_only=True, subset_by_index=[0, n - 1])
    return np.sqrt(np.maximum(w2, 0)) / (2 * np.pi)


def rayleigh(K: np.ndarray, M: np.ndarray, f1_hz: float, f2_hz: float, zeta: float) -> np.ndarray:
    """Rayleigh damping C = a M + b K with damping ratio ``zeta`` at f1 and f2 (Hz)."""
    w1, w2 = 2 * np.pi * f1_hz, 2 * np.pi * f2_hz
    a = 2 * zeta * w1 * w2 / (w1 + w2)
    b = 2 * zeta / (w1 + w2)
    return a * M + b * K


@dataclass(frozen=True)
class Stiffening:
    """Cubic hardening: M = EI (k + beta k^3 / k_ref^2). beta 0 = linear; k_ref in 1/m (a number or (n_el, 1))."""

    beta: float = 0.0
    k_ref: float | np.ndarray = 1.0


@dataclass(frozen=True)
class Creep:
    """Maxwell creep in ``elements``: dk_c/dt = (k_g + k_mean - k_c) / tau_s. tau_s inf = none."""

    elements: tuple[int, ...] = ()
    tau_s: float = float("inf")
    k_g: float = 0.0


def newmark(mesh: Mesh, K: np.ndarray, M: np.ndarray, C: np.ndarray, load, n_steps: int, dt: float,
            stiffening: Stiffening = Stiffening(), creep: Creep = Creep(), record_every: int = 1,
            newton_tol: float = 1e-10, max_newton: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Integrate M u'' + C u' + f_int(u) = f(t) from rest (u = u' = 0 at t = 0, f(0) should be 0).

    ``load(i)`` -> f at step i (n_dof,), i = 0..n_steps. Returns (u at every ``record_every``-th step
    (n_rec, n_dof), creep eigen-curvature at the same steps (n_rec, len(creep.elements))).
    """
    g, bN = 0.5, 0.25
    a0, a1, a2 = 1 / (bN * dt ** 2), g / (bN * dt), 1 / (bN * dt)
    a3, a4, a5 = 1 / (2 * bN) - 1, g / bN - 1, dt / 2 * (g / bN - 2)
    n = len(K)
    u, v, acc = np.zeros(n), np.zeros(n), np.zeros(n)
    weak = np.asarray(creep.elements, int)
    Fc = mesh.eigen_curvature_load(weak) if len(weak) else np.zeros((n, 0))
    Kc = mesh.mean_curvature(weak) if len(weak) else np.zeros((0, n))
    kc = np.zeros(len(weak))
    has_creep = len(weak) > 0 and np.isfinite(creep.tau_s)
    nonlinear = stiffening.beta > 0
    Keff = K + a0 * M + a1 * C
    lu = lu_factor(Keff)
    B = mesh.curvature_operator()
    wg = mesh.EI_g * GAUSS_W[None] * mesh.lengths[:, None]
    c3 = stiffening.beta / stiffening.k_ref ** 2 if nonlinear else 0.0
    rec_u, rec_k = [u.copy()], [kc.copy()]
    for i in range(1, n_steps + 1):
        f = load(i) + (Fc @ kc if has_creep else 0.0)
        rhs_hist = M @ (a0 * u + a2 * v + a3 * acc) + C @ (a1 * u + a4 * v + a5 * acc)
        un = lu_solve(lu, f + rhs_hist)
        if nonlinear:
            for _ in range(max_newton):
                k = np.einsum("egi,ei->eg", B, mesh.gather(un))
                f_nl = mesh.assemble_vec(np.einsum("eg,egi->ei", wg * c3 * k ** 3, B))
                res = (Keff @ un + f_nl) - (f + rhs_hist)
                if np.linalg.norm(res) <= newton_tol * max(np.linalg.norm(f + rhs_hist), 1e-30):
                    break
                Kt = Keff + mesh.assemble(np.einsum("eg,egi,egj->eij", wg * 3 * c3 * k ** 2, B, B))
                un = un - np.linalg.solve(Kt, res)
            else:
                raise RuntimeError(f"beam: Newton iterations did not converge at step {i} ({max_newton} iterations)")
        an = a0 * (un - u) - a2 * v - a3 * acc
        v = v + dt * ((1 - g) * acc + g * an)
        u, acc = un, an
        if has_creep:
            kc = kc + dt * (creep.k_g + Kc @ u - kc) / creep.tau_s
        if i % record_every == 0:
            rec_u.append(u.copy())
            rec_k.append(kc.copy())
    return np.array(rec_u), np.array(rec_k)
