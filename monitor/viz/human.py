"""Numbers for people: durations, damage, stress and tension in the units every display shares.

Displays (terminal summary, HTML page, plots, Rerun names) use MPa for stress and kN for
tension; the JSON report stays SI (docs/REPORT_FORMAT.md). Extreme or non-finite values are
put in words instead of printed as e.g. ``4.1e+107 d``.
"""

from __future__ import annotations

import math

HOURS_PER_DAY = 24.0
DAYS_PER_YEAR = 365.25
# beyond this a remaining life is "more than 1,000 years": no mooring part is kept that long,
# and the digits would only suggest a precision the S-N curve's tail does not have
LONG_LIFE_YEARS = 1000.0


def _sig(x: float, digits: int = 2) -> str:
    """``x`` to ``digits`` significant figures without an exponent, thousands separated."""
    if x == 0:
        return "0"
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(x))))
    rounded = round(x, decimals)
    return f"{rounded:,.{decimals}f}" if decimals else f"{rounded:,.0f}"


def duration_text(days: float) -> str:
    """A span of time in the unit that suits it: "40 min", "7.8 h", "12 days", "about 40
    years", "more than 1,000 years"; "unlimited" when infinite, "n/a" when not a number."""
    if math.isnan(days):
        return "n/a"
    if math.isinf(days):
        return "unlimited"
    hours = days * HOURS_PER_DAY
    if hours < 1.0:
        return f"{_sig(hours * 60.0)} min"
    if hours < 48.0:
        return f"{_sig(hours)} h"
    if days < 2 * DAYS_PER_YEAR:
        return f"{_sig(days)} days"
    years = days / DAYS_PER_YEAR
    if years > LONG_LIFE_YEARS:
        return f"more than {LONG_LIFE_YEARS:,.0f} years"
    return f"about {_sig(years)} years"


def remaining_life_text(days: float) -> str:
    """Remaining life in words: "none (failed)" at 0, "unlimited (no damage accrues)" when
    nothing accrues, else :func:`duration_text`."""
    if days == 0:
        return "none (failed)"
    if math.isinf(days):
        return "unlimited (no damage accrues)"
    return duration_text(days)


def number_text(x: float, digits: int = 3) -> str:
    """A dimensionless figure (damage, rate, ratio): 3 significant figures, an exponent only
    below 0.001 or from 1e6; "n/a" / "unlimited" for NaN / infinity."""
    if math.isnan(x):
        return "n/a"
    if math.isinf(x):
        return "unlimited" if x > 0 else "-unlimited"
    if x != 0 and (abs(x) < 1e-3 or abs(x) >= 1e6):
        return f"{x:.{digits - 1}e}"
    return _sig(x, digits)


def stress_text(pa: float) -> str:
    """A stress in MPa, e.g. "142 MPa"."""
    return "n/a" if not math.isfinite(pa) else f"{_sig(pa / 1e6, 3)} MPa"


def tension_text(n: float) -> str:
    """A tension in kN, e.g. "22.1 kN"."""
    return "n/a" if not math.isfinite(n) else f"{_sig(n / 1e3, 3)} kN"


def ratio_text(x: float) -> str:
    """A ratio for "takes N times the damage": 2 significant figures ("15", "1.7", "340")."""
    return "n/a" if not math.isfinite(x) else _sig(x, 2)
