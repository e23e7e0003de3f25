"""Inverse catenary problem: measured top tension -> fairlead offset (span) and top angle.

At a fixed fairlead height the top tension grows monotonically with the span (the end
stiffness is positive definite), so the span is found by a bracketed Newton iteration using
the exact stiffness, dT/dx = (H dH/dx + V dV/dx) / T, with bisection whenever Newton leaves
the bracket. The forward direction (offset and heave -> tension) is `solve` itself.
"""

from __future__ import annotations

import numpy as np

from models.catenary.line import Line, LineSolution, broadcast_pair, solve


def span_from_top_tension(line: Line, t_top, height, rtol: float = 1e-12,
                          max_iter: int = 100) -> LineSolution:
    """Fairlead span giving top tension `t_top` (N) at `height` (m); vectorised. Returns the
    solved line there: `.span` is the offset, `.top_angle` the line angle at the fairlead.
    A tension below the slack minimum (span 0) or, for an inextensible line, beyond any
    reachable span is a ValueError."""
    t, z = broadcast_pair(t_top, height, ("t_top", "height"))
    if not np.all(np.isfinite(t)) or np.any(t <= 0.0):
        raise ValueError("t_top must be finite and > 0")
    if not np.all(np.isfinite(z)):
        raise ValueError("height must be finite")
    shape = t.shape
    t = t.ravel().copy()
    z = z.ravel().copy()
    length = line.length
    lo = np.zeros_like(t)
    t_lo = solve(line, lo, z).t_top
    if np.any(t < t_lo * (1.0 - rtol)):
        i = int(np.argmax(t < t_lo * (1.0 - rtol)))
        raise ValueError(f"t_top {t[i]!r} N is below the slack minimum {t_lo[i]!r} N "
                         f"(fairlead above the anchor) at height {z[i]!r} m")
    reach = np.sqrt(np.maximum(length**2 - z**2, 0.0))
    if line.inextensible:
        hi = reach * (1.0 - 1e-12)
        t_hi = solve(line, hi, z).t_top
        if np.any(t > t_hi):
            i = int(np.argmax(t > t_hi))
            raise ValueError(f"t_top {t[i]!r} N is beyond an inextensible line's reach at "
                             f"height {z[i]!r} m (max {t_hi[i]!r} N)")
    else:
        hi = np.maximum(reach, 1e-3 * length)
        t_hi = solve(line, hi, z).t_top
        for _ in range(200):  # stretch until the bracket holds the target
            short = t_hi < t
            if not short.any():
                break
            hi[short] = hi[short] * 1.05 + 1e-3 * length
            t_hi[short] = solve(line, hi[short], z[short]).t_top
        else:
            raise ValueError("could not bracket the requested top tension")
    x = np.where(t_hi > t_lo, lo + (hi - lo) * (t - t_lo) / np.maximum(t_hi - t_lo, 1e-300), lo)
    for _ in range(max_iter):
        sol = solve(line, x, z)
        tt = sol.t_top
        f = tt - t
        done = np.abs(f) <= rtol * t
        if done.all():
            break
        above = f > 0
        hi = np.where(above, x, hi)
        lo = np.where(above, lo, x)
        k = sol.stiffness
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (sol.h * k[:, 0, 0] + sol.v_top * k[:, 1, 0]) / tt
            x_new = x - f / slope
        outside = ~np.isfinite(x_new) | (x_new <= lo) | (x_new >= hi)
        x = np.where(done, x, np.where(outside, 0.5 * (lo + hi), x_new))
    else:
        raise ValueError("span_from_top_tension did not converge")
    return solve(line, x.reshape(shape), z.reshape(shape))

