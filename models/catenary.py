"""Cable statics: catenary models of the mooring line (issue 4; seeds 000-004).

Stable public entry points (implementations live in the `catenary_*` modules):
- `solve_line(span, height, length, weight, ea=inf, seabed=True, seabed_friction=0.0)`
- `Segment`, `Joint`, `Line`, `solve(line, span, height)` for multi-segment lines
- `LineSolution` (tensions, grounded length, stiffness, `profile(n)`), `REGIMES`
- `vaps_mooring()` (seed 004's line), `TensionTable` (fast motion -> tension lookup)
"""

from models.catenary_line import (
    REGIMES,
    Joint,
    Line,
    LineSolution,
    Profile,
    Segment,
    solve,
    solve_line,
)
from models.catenary_table import TensionTable, TopForces
from models.catenary_vaps import VAPS_DEPTH, vaps_mooring

__all__ = ["REGIMES", "VAPS_DEPTH", "Joint", "Line", "LineSolution", "Profile", "Segment",
           "TensionTable", "TopForces", "solve", "solve_line", "vaps_mooring"]
