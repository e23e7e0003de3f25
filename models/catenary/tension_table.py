"""Precomputed fairlead-force table for fast motion -> tension estimates.

Exact multi-segment solves (models.catenary.line.solve) on a grid of fairlead positions,
interpolated with bicubic Hermite patches that use the exact end stiffness (dH/dx, dH/dz,
dV/dx, dV/dz) as node slopes, so the interpolant matches values and slopes at every node.
The accuracy is measured when the table is built, against exact solves at every cell centre
and edge midpoint, and reported in `max_error` / `max_relative_error`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models._jit import kernel
from models.catenary.line import Line, broadcast_pair, solve


@kernel()
def _cell(g, x, k):
    """Index i in [0, len(g) - 2] with g[i] <= x < g[i + 1] (clamped at the ends), trying
    ``k`` (the previous point's cell: estimates are consecutive samples) before a bisection."""
    n = g.shape[0]
    if 0 <= k <= n - 2 and g[k] <= x < g[k + 1]:
        return k
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if x >= g[mid]:
            lo = mid
        else:
            hi = mid
    return lo


@kernel()
def _hermite(xg, zg, coef, xs, zs, out, want_slopes):
    """Evaluate the bicubic Hermite tables `coef` (nq, nx, nz, 4: f, f_x, f_z, f_xz) at points;
    out (n, nq, 3): value, d/dx, d/dz."""
    nq = coef.shape[0]
    i = -1
    j = -1
    for p in range(xs.shape[0]):
        x = xs[p]
        z = zs[p]
        i = _cell(xg, x, i)
        j = _cell(zg, z, j)
        dx = xg[i + 1] - xg[i]
        dz = zg[j + 1] - zg[j]
        u = (x - xg[i]) / dx
        v = (z - zg[j]) / dz
        # cubic Hermite basis and derivatives in u and v
        u2 = u * u
        u3 = u2 * u
        v2 = v * v
        v3 = v2 * v
        bu0 = 2 * u3 - 3 * u2 + 1
        bu1 = u3 - 2 * u2 + u
        bu2 = -2 * u3 + 3 * u2
        bu3 = u3 - u2
        bv0 = 2 * v3 - 3 * v2 + 1
        bv1 = v3 - 2 * v2 + v
        bv2 = -2 * v3 + 3 * v2
        bv3 = v3 - v2
        for q in range(nq):
            # per corner (i, j), (i+1, j), (i, j+1), (i+1, j+1): value, x-slope (scaled to
            # u), z-slope (to v), cross
            a0, a1, a2, a3 = coef[q, i, j, 0], coef[q, i, j, 1], coef[q, i, j, 2], coef[q, i, j, 3]
            b0, b1, b2, b3 = (coef[q, i + 1, j, 0], coef[q, i + 1, j, 1], coef[q, i + 1, j, 2],
                              coef[q, i + 1, j, 3])
            c0, c1, c2, c3 = (coef[q, i, j + 1, 0], coef[q, i, j + 1, 1], coef[q, i, j + 1, 2],
                              coef[q, i, j + 1, 3])
            d0, d1, d2, d3 = (coef[q, i + 1, j + 1, 0], coef[q, i + 1, j + 1, 1],
                              coef[q, i + 1, j + 1, 2], coef[q, i + 1, j + 1, 3])
            f = (bv0 * (bu0 * a0 + bu1 * dx * a1 + bu2 * b0 + bu3 * dx * b1)
                 + bv1 * dz * (bu0 * a2 + bu1 * dx * a3 + bu2 * b2 + bu3 * dx * b3)
                 + bv2 * (bu0 * c0 + bu1 * dx * c1 + bu2 * d0 + bu3 * dx * d1)
                 + bv3 * dz * (bu0 * c2 + bu1 * dx * c3 + bu2 * d2 + bu3 * dx * d3))
            out[p, q, 0] = f
            if want_slopes:
                du0 = 6 * u2 - 6 * u
                du1 = 3 * u2 - 4 * u + 1
                du2 = -6 * u2 + 6 * u
                du3 = 3 * u2 - 2 * u
                dv0 = 6 * v2 - 6 * v
                dv1 = 3 * v2 - 4 * v + 1
                dv2 = -6 * v2 + 6 * v
                dv3 = 3 * v2 - 2 * v
                fu = (bv0 * (du0 * a0 + du1 * dx * a1 + du2 * b0 + du3 * dx * b1)
                      + bv1 * dz * (du0 * a2 + du1 * dx * a3 + du2 * b2 + du3 * dx * b3)
                      + bv2 * (du0 * c0 + du1 * dx * c1 + du2 * d0 + du3 * dx * d1)
                      + bv3 * dz * (du0 * c2 + du1 * dx * c3 + du2 * d2 + du3 * dx * d3))
                fv = (dv0 * (bu0 * a0 + bu1 * dx * a1 + bu2 * b0 + bu3 * dx * b1)
                      + dv1 * dz * (bu0 * a2 + bu1 * dx * a3 + bu2 * b2 + bu3 * dx * b3)
                      + dv2 * (bu0 * c0 + bu1 * dx * c1 + bu2 * d0 + bu3 * dx * d1)
                      + dv3 * dz * (bu0 * c2 + bu1 * dx * c3 + bu2 * d2 + bu3 * dx * d3))
                out[p, q, 1] = fu / dx
                out[p, q, 2] = fv / dz


@dataclass(frozen=True)
class TopForces:
    """Fairlead force components (N) and, if requested, the end stiffness (N/m)."""

    h: np.ndarray
    v: np.ndarray
    t: np.ndarray
    stiffness: np.ndarray | None = None  # (..., 2, 2) [[dH/dx, dH/dz], [dV/dx, dV/dz]]


class TensionTable:
    """Fairlead force of `line` tabulated over span in `x_range` and height in `z_range`
    (m, fairlead relative to the anchor).

    Starts from `nx` x `nz` evenly spaced nodes and halves every grid interval whose check
    points miss the exact solution by more than `rtol` (relative to the largest node tension of
    the cell), up to `max_refinements` passes, so steep regions (a line going taut) get dense
    nodes. The check points are all cell centres and edge midpoints; the worst remaining
    errors are `max_error` (N, worst |dH| or |dV|) and `max_relative_error`.
    top_tension(x, z) / forces(x, z, stiffness=True) evaluate millions of points per second;
    points outside the table are a ValueError."""

    def __init__(self, line: Line, x_range: tuple[float, float], z_range: tuple[float, float],
                 nx: int = 129, nz: int = 17, rtol: float = 1e-4,
                 max_refinements: int = 4) -> None:
        x0, x1 = (float(v) for v in x_range)
        z0, z1 = (float(v) for v in z_range)
        if not (np.isfinite([x0, x1, z0, z1]).all() and x1 > x0 >= 0.0 and z1 > z0):
            raise ValueError(f"need 0 <= x_range[0] < x_range[1] and z_range[0] < z_range[1], "
                             f"got {x_range!r}, {z_range!r}")
        if line.seabed and z0 < 0.0:
            raise ValueError(f"z_range must be >= 0 above a seabed, got {z_range!r}")
        if nx < 2 or nz < 2:
            raise ValueError(f"need nx, nz >= 2, got {nx}, {nz}")
        if not rtol > 0.0:
            raise ValueError(f"rtol must be > 0, got {rtol!r}")
        self.line = line
        self.x = np.linspace(x0, x1, nx)
        self.z = np.linspace(z0, z1, nz)
        for _ in range(max_refinements + 1):
            nodes = self._build()
            bad_x, bad_z = self._check(nodes, rtol)
            if not (bad_x.any() or bad_z.any()) or _ == max_refinements:
                break
            self.x = np.sort(np.concatenate([self.x, 0.5 * (self.x[1:] + self.x[:-1])[bad_x]]))
            self.z = np.sort(np.concatenate([self.z, 0.5 * (self.z[1:] + self.z[:-1])[bad_z]]))

    def _build(self):
        X, Z = np.meshgrid(self.x, self.z, indexing="ij")
        sol = solve(self.line, X, Z)
        # cross slopes d2/dxdz by central differences of the exact x-slopes
        dz = 1e-4 * float(np.min(np.diff(self.z)))
        z_dn = np.maximum(Z - dz, 0.0) if self.line.seabed else Z - dz
        up = solve(self.line, X, Z + dz)
        dn = solve(self.line, X, z_dn)
        step = Z + dz - z_dn
        k = sol.stiffness
        coef = np.empty((2, self.x.size, self.z.size, 4))
        coef[0] = np.stack([sol.h, k[..., 0, 0], k[..., 0, 1],
                            (up.stiffness[..., 0, 0] - dn.stiffness[..., 0, 0]) / step], axis=-1)
        coef[1] = np.stack([sol.v_top, k[..., 1, 0], k[..., 1, 1],
                            (up.stiffness[..., 1, 0] - dn.stiffness[..., 1, 0]) / step], axis=-1)
        self._coef = coef
        return sol

    def _check(self, sol, rtol: float) -> tuple[np.ndarray, np.ndarray]:
        """Set max_error/max_relative_error; return the x and z intervals to refine."""
        xm = 0.5 * (self.x[1:] + self.x[:-1])
        zm = 0.5 * (self.z[1:] + self.z[:-1])
        t = np.hypot(sol.h, sol.v_top)
        t_x = np.maximum(t[:-1], t[1:])  # per x-interval, at z nodes
        t_z = np.maximum(t[:, :-1], t[:, 1:])
        t_c = np.maximum(t_x[:, :-1], t_x[:, 1:])
        rel = []
        worst = 0.0
        for xs, zs, ref in ((xm, zm, t_c), (xm, self.z, t_x), (self.x, zm, t_z)):
            X, Z = np.meshgrid(xs, zs, indexing="ij")
            exact = solve(self.line, X, Z)
            approx = self._eval(X.ravel(), Z.ravel(), False)[:, :, 0]
            err = np.maximum(np.abs(approx[:, 0] - exact.h.ravel()),
                             np.abs(approx[:, 1] - exact.v_top.ravel())).reshape(X.shape)
            worst = max(worst, float(err.max()))
            rel.append(err / np.maximum(ref, np.finfo(float).tiny))
        self.max_error = worst
        self.max_relative_error = float(max(r.max() for r in rel))
        bad_c, bad_xm, bad_zm = (r > rtol for r in rel)
        bad_x = bad_c.any(axis=1) | bad_xm.any(axis=1)
        bad_z = bad_c.any(axis=0) | bad_zm.any(axis=0)
        return bad_x, bad_z

    def _eval(self, x: np.ndarray, z: np.ndarray, slopes: bool) -> np.ndarray:
        out = np.empty((x.size, 2, 3))
        _hermite(self.x, self.z, self._coef, x, z, out, slopes)
        return out

    def _points(self, x, z) -> tuple[np.ndarray, np.ndarray, tuple]:
        xa, za = broadcast_pair(x, z, ("span", "height"))
        xf = xa.ravel()
        zf = za.ravel()
        if xf.size:
            lo_x, hi_x, lo_z, hi_z = xf.min(), xf.max(), zf.min(), zf.max()
            if not (lo_x >= self.x[0] and hi_x <= self.x[-1]):
                raise ValueError(f"span outside the table [{self.x[0]}, {self.x[-1]}] m "
                                 f"(got {lo_x!r} .. {hi_x!r}; NaN counts as outside)")
            if not (lo_z >= self.z[0] and hi_z <= self.z[-1]):
                raise ValueError(f"height outside the table [{self.z[0]}, {self.z[-1]}] m "
                                 f"(got {lo_z!r} .. {hi_z!r}; NaN counts as outside)")
        return xf, zf, xa.shape

    def forces(self, x, z, stiffness: bool = False) -> TopForces:
        """Fairlead H, V, T (and the end stiffness if asked) at span x, height z."""
        xf, zf, shape = self._points(x, z)
        out = self._eval(xf, zf, stiffness)
        h = out[:, 0, 0].reshape(shape)
        v = out[:, 1, 0].reshape(shape)
        k = None
        if stiffness:
            k = out[:, :, 1:].reshape(shape + (2, 2))
        return TopForces(h, v, np.hypot(h, v), k)

    def top_tension(self, x, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(H, V, T) at the fairlead (N) for span x and height z (m), vectorised."""
        f = self.forces(x, z)
        return f.h, f.v, f.t
