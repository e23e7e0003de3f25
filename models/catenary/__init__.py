"""Cable statics: catenary models of the mooring line (issue 4; seeds 000-004).

Stable public entry points. The modules: `line` (segments, `solve`, `LineSolution`), `kernel`
(its compiled residuals and Newton loop), `inverse` (top tension -> span), `tension_table`
(`TensionTable`), `current` (steady current), `vaps` (seed 004's line), `closed_forms` (the
seeds' own formulas).
- `solve_line(span, height, length, weight, ea=inf, seabed=True, seabed_friction=0.0)`
- `Segment`, `Joint`, `Line`, `solve(line, span, height)` for multi-segment lines
- `LineSolution` (tensions, grounded length, joint tensions, 2x2 end stiffness, `profile(n)`)
- `span_from_top_tension(line, t_top, height)`: measured top tension -> offset, top angle
- `TensionTable(line, x_range, z_range)`: precomputed fast motion -> tension lookup
- `vaps_mooring()`: seed 004's multi-segment line; `VAPS_DEPTH`
- `solve_in_current(line, span, height, current, Drag(...))`: steady current on the line
"""

from models.catenary.current import CurrentSolution, Drag, solve_in_current
from models.catenary.inverse import span_from_top_tension
from models.catenary.line import (
    REGIMES,
    Joint,
    Line,
    LineSolution,
    Profile,
    Segment,
    solve,
    solve_line,
)
from models.catenary.tension_table import TensionTable, TopForces
from models.catenary.vaps import VAPS_DEPTH, vaps_mooring

__all__ = ["REGIMES", "VAPS_DEPTH", "CurrentSolution", "Drag", "Joint", "Line", "LineSolution",
           "Profile", "Segment", "TensionTable", "TopForces", "solve", "solve_in_current",
           "solve_line", "span_from_top_tension", "vaps_mooring"]
