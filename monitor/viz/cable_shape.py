"""Cable shape for the 3D view: measured or estimated top tension -> the line's profile.

Uses the catenary models of :mod:`models.catenary` (issue 4): the fairlead span that gives the
top tension at the fairlead height (inverse problem), then that solution's profile.
"""

from __future__ import annotations

import numpy as np

from models.catenary import Line, span_from_top_tension
from monitor.viz.rerun_sink import ShapeProvider


def catenary_shape_provider(line: Line, height_m: float, n_points: int = 40) -> ShapeProvider:
    """A :data:`~monitor.viz.rerun_sink.ShapeProvider` for a ``models.catenary.Line``.

    ``height_m`` is the fairlead height above the anchor (the water depth for a surface buoy).
    The returned callable raises ValueError for a tension the line cannot have (the sink then
    skips that frame).
    """
    if not np.isfinite(height_m) or height_m <= 0:
        raise ValueError(f"cable shape: fairlead height {height_m!r} m must be > 0")

    def shape(top_tension_N: float) -> tuple[np.ndarray, np.ndarray]:
        solution = span_from_top_tension(line, float(top_tension_N), float(height_m))
        if np.ndim(solution.h) != 0:
            solution = solution[()]
        profile = solution.profile(n_points)
        return profile.x, profile.z

    return shape
