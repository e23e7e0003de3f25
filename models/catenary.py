"""Cable statics: catenary models of the mooring line (issue 4; seeds 000, 001, 003, 004).

Stable public entry points (implementations live in the `catenary_*` modules):
- `solve_line(span, height, length, weight, ea=inf, seabed=True, seabed_friction=0.0)`
- `Segment`, `Joint`, `Line`, `solve(line, span, height)` for multi-segment lines
- `LineSolution` (tensions, grounded length, stiffness, `profile(n)`), `REGIMES`
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

__all__ = ["REGIMES", "Joint", "Line", "LineSolution", "Profile", "Segment", "solve",
           "solve_line"]
