"""Method 2: discretization on the sphere + Richardson extrapolation (see the package docstring)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline, make_interp_spline
from scipy.sparse import csr_matrix, diags
from scipy.sparse.linalg import spsolve

from .geometry import align, exp_map, normalized_derivatives, states_from_path, tangent_basis

# ----------------------------------------------------------------------------------------------------
# method 2: discretization on the sphere + Richardson extrapolation


@dataclass
class DiscreteReference:
    """Discrete optimum(s) on the sphere and the Richardson-extrapolated energy.

    Attributes:
        E_star: extrapolated energy [1/s^3] (or the finest level's if not extrapolated).
        levels: N (points per keyframe interval) of each level.
        energies: discrete optimal energy at each level.
        t, u: grid times (M,) and unit quaternions (M, 4) of the finest level.
    """

    E_star: float
    levels: tuple
    energies: tuple
    t: np.ndarray
    u: np.ndarray
    iterations: tuple = ()

    def states(self, t: np.ndarray) -> np.ndarray:
        """(n, 16) approximate (u, V, A, J) by a quintic spline through the finest grid (for a start)."""
        spl = make_interp_spline(self.t, self.u, k=5)
        q, q1, q2, q3 = (spl(t, nu) for nu in range(4))
        return states_from_path(*normalized_derivatives(q, q1, q2, q3))


def _grid(times: np.ndarray, N: int):
    K = len(times)
    t = np.concatenate(
        [np.linspace(times[j], times[j + 1], N + 1)[:-1] for j in range(K - 1)] + [times[-1:]]
    )
    fixed = np.zeros(len(t), dtype=bool)
    fixed[::N] = True
    return t, fixed


def _discrete_solve(t, fixed, u0, tol=1e-15, max_iter=200):
    """Minimize sum_g w_g |P(u_g) D2_g|^2 over free unit points (Levenberg-Marquardt, exp-map steps)."""
    M = len(t)
    g = np.arange(1, M - 1)
    h1 = t[g] - t[g - 1]
    h2 = t[g + 1] - t[g]
    al = 2.0 / (h1 * (h1 + h2))
    ga = 2.0 / (h2 * (h1 + h2))
    be = -(al + ga)
    s = np.sqrt(0.5 * (h1 + h2))
    free = np.flatnonzero(~fixed)
    col = -np.ones(M, dtype=int)
    col[free] = np.arange(len(free))
    nfree = len(free)

    def resid(u):
        d = al[:, None] * u[g - 1] + be[:, None] * u[g] + ga[:, None] * u[g + 1]
        ud = np.sum(u[g] * d, axis=1)
        r = s[:, None] * (d - u[g] * ud[:, None])
        return r, d, ud

    u = u0.copy()
    r, d, ud = resid(u)
    E = float(np.sum(r * r))
    mu = 1e-6
    it = 0
    for it in range(1, max_iter + 1):
        B = tangent_basis(u)  # (M, 3, 4)
        P = np.eye(4)[None] - u[g][:, :, None] * u[g][:, None, :]  # (G, 4, 4)
        rows, cols, vals = [], [], []
        ridx = (np.arange(len(g))[:, None] * 4 + np.arange(4)[None, :])  # (G, 4)
        for off, coef in ((-1, al), (1, ga)):
            nb = g + off
            ok = col[nb] >= 0
            blk = s[ok, None, None] * coef[ok, None, None] * np.einsum("gij,gkj->gik", P[ok], B[nb[ok]])
            rr = np.repeat(ridx[ok][:, :, None], 3, axis=2)
            cc = np.repeat((col[nb[ok]][:, None] * 3 + np.arange(3))[:, None, :], 4, axis=1)
            rows.append(rr.ravel()), cols.append(cc.ravel()), vals.append(blk.ravel())
        ok = col[g] >= 0
        Bg = B[g[ok]]  # (n, 3, 4)
        blk = (be[ok] - ud[ok])[:, None, None] * np.transpose(Bg, (0, 2, 1)) - u[g[ok]][:, :, None] * np.einsum(
            "gj,gkj->gk", d[ok], Bg
        )[:, None, :]
        blk *= s[ok, None, None]
        rr = np.repeat(ridx[ok][:, :, None], 3, axis=2)
        cc = np.repeat((col[g[ok]][:, None] * 3 + np.arange(3))[:, None, :], 4, axis=1)
        rows.append(rr.ravel()), cols.append(cc.ravel()), vals.append(blk.ravel())
        Jm = csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(4 * len(g), 3 * nfree),
        )
        JtJ = (Jm.T @ Jm).tocsc()
        grad = Jm.T @ r.ravel()
        diag = JtJ.diagonal()
        while True:
            H = JtJ + diags(mu * (diag + 1e-12))
            step = -spsolve(H.tocsc(), grad).reshape(nfree, 3)
            un = u.copy()
            un[free] = exp_map(u[free], np.einsum("nk,nkj->nj", step, B[free]))
            rn, dn, udn = resid(un)
            En = float(np.sum(rn * rn))
            if En <= E:
                break
            mu *= 10.0
            if mu > 1e12:
                return u, E, it
        dE = E - En
        u, r, d, ud, E = un, rn, dn, udn, En
        mu = max(mu / 10.0, 1e-12)
        if dE <= tol * E:
            break
    return u, E, it


def discrete_sphere_reference(
    times: np.ndarray,
    quats: np.ndarray,
    n_levels: tuple = (64, 128, 256),
    extrapolate: bool = True,
) -> DiscreteReference:
    """E* by a fine discretization on the sphere with Richardson extrapolation (independent of solve_bvp).

    N points per keyframe interval (uniform within each interval); the keyframes are fixed grid points,
    the other points are unit quaternions moved by exponential-map steps (no constraint needed). The
    discrete energy is sum over interior grid points g of w_g |P(u_g) D2_g|^2, with D2_g the (non-uniform
    at keyframes) three-point second difference, P(u) = I - u u^T, w_g = (h_left + h_right)/2. It is
    minimized by Levenberg-Marquardt (exact sparse normal equations). Levels are solved coarse to fine
    (each starts from the previous one, interpolated); E_N = E* + c h^2 + O(h^3), so two Richardson
    steps (p = 2, then p = 3) are taken with three levels that double N.

    Args:
        times: (K,) keyframe times [s]; quats: (K, 4) keyframe quaternions.
        n_levels: N per level, each the double of the previous for the extrapolation.
        extrapolate: if False, E_star is the finest level's discrete energy.
    Returns:
        DiscreteReference.
    """
    times = np.asarray(times, dtype=float)
    q = align(quats)
    cs = CubicSpline(times, q, bc_type="natural")
    energies, its = [], []
    prev = None
    for N in n_levels:
        t, fixed = _grid(times, N)
        if prev is None:
            u0 = cs(t)
        else:
            u0 = make_interp_spline(prev[0], prev[1], k=5)(t)
        u0 /= np.linalg.norm(u0, axis=1, keepdims=True)
        u0[fixed] = q
        u, E, it = _discrete_solve(t, fixed, u0)
        energies.append(E)
        its.append(it)
        prev = (t, u)
    E = energies[-1]
    if extrapolate and len(energies) >= 2:
        e = list(energies)
        # Richardson: first eliminate h^2, then h^3 (levels double N)
        e = [(4 * b - a) / 3 for a, b in zip(e[:-1], e[1:])]
        if len(e) >= 2:
            e = [(8 * b - a) / 7 for a, b in zip(e[:-1], e[1:])]
        E = e[-1]
    return DiscreteReference(
        E_star=float(E), levels=tuple(n_levels), energies=tuple(energies), t=prev[0], u=prev[1],
        iterations=tuple(its),
    )
