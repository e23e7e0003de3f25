"""The finding of a replay in words: what was replayed, the verdict per component, how the
components compare, loads beyond what the model covers, and what to do next.

The HTML page (its first section) and the terminal summary (``replay.report.summary_text``)
both print :func:`findings` of the parsed report, so they say the same thing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Mapping

import numpy as np

from monitor.viz.human import (DAYS_PER_YEAR, duration_text, number_text, ratio_text,
                               remaining_life_text, stress_text, tension_text)
from monitor.viz.report_data import Component, Report


@dataclass(frozen=True)
class Findings:
    """Sentences, grouped as the page shows them."""

    replayed: list[str] = field(default_factory=list)
    verdicts: list[str] = field(default_factory=list)
    comparisons: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    next_steps: list[str] = field(default_factory=list)

    def sections(self) -> list[tuple[str, list[str]]]:
        """(heading, sentences) of the non-empty groups, in reading order."""
        return [(h, s) for h, s in (
            ("What was replayed", self.replayed), ("Verdict per component", self.verdicts),
            ("Comparison", self.comparisons), ("Beyond the model", self.warnings),
            ("What to do next", self.next_steps)) if s]


def describe(c: Component) -> str:
    """A component's name with what it is: "conductor (left-lay conductor)", "chain (axial,
    S-N strength / 2)"."""
    what = f"{c.lay}-lay {c.kind}" if c.lay and c.kind else c.kind
    extra = [what] if what else []
    if c.derating and c.derating != 1.0:
        extra.append(f"S-N strength / {c.derating:g}")
    return f"{c.name} ({', '.join(extra)})" if extra else c.name


def _utc(t_ns: int) -> str:
    return datetime.fromtimestamp(t_ns / 1e9, tz=timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def failure_time_days(c: Component, start_ns: int, span_days: float) -> tuple[float, bool]:
    """When the damage (incl. the open residue) reached 1, in days after ``start_ns``, and
    whether that comes from the damage history (True) or from the average rate over the
    replay (False: no history, or the history ends before the crossing)."""
    h = c.damage_history
    if h is not None and len(h.t_s):
        d = h.columns.get("damage", h.columns["damage_committed"])
        above = np.flatnonzero(d >= 1.0)
        if len(above):
            k = int(above[0])
            t = h.t_s[k]
            if k > 0 and d[k] > d[k - 1]:  # linear between the two history points
                t = h.t_s[k - 1] + (1.0 - d[k - 1]) / (d[k] - d[k - 1]) * (t - h.t_s[k - 1])
            return max(0.0, (t - start_ns / 1e9) / 86400.0), True
    return span_days / c.damage, False


def _verdict(c: Component, r: Report, span_days: float) -> str:
    design = r.design_life_years
    head = f"{describe(c)}: "
    if c.damage >= 1.0:
        days, from_history = failure_time_days(c, r.time_start_ns, span_days)
        how = "" if from_history else " at the average rate"
        return (head + f"FAILED: Miner damage {number_text(c.damage)} (1 = predicted failure), "
                f"reached 1 after {duration_text(days)}{how}; peak stress "
                f"{stress_text(c.max_stress_Pa)}.")
    if c.damage <= 0.0:
        return (head + f"no fatigue damage (peak stress {stress_text(c.max_stress_Pa)}, "
                "no cycle that the S-N curve counts).")
    text = (head + f"damage {number_text(c.damage)} in {duration_text(span_days)} "
            f"(peak stress {stress_text(c.max_stress_Pa)})")
    if not math.isfinite(c.remaining_life_days):
        return text + "; none accrued at the end of the replay, so no end of life is projected."
    text += (f"; at the latest rate ({number_text(c.damage_rate_per_day)} per day) it fails in "
             f"{remaining_life_text(c.remaining_life_days)}")
    if design:
        short = c.remaining_life_days < design * DAYS_PER_YEAR
        text += (f", short of the {design:g}-year design life" if short
                 else f", beyond the {design:g}-year design life")
    return text + "."


def _comparisons(r: Report) -> list[str]:
    """Each further component against the first of the same kind (the configuration's order:
    the as-built part first), larger damage first."""
    out = []
    comps = list(r.components.values())
    for c in comps[1:]:
        ref = next(x for x in comps if x.kind == c.kind)
        if ref is c:
            continue
        big, small = (ref, c) if ref.damage >= c.damage else (c, ref)
        if big.damage <= 0:
            out.append(f"Neither {describe(ref)} nor {describe(c)} takes any damage.")
            continue
        if small.damage <= 0:
            out.append(f"{describe(big)} takes damage {number_text(big.damage)}; "
                       f"{describe(small)} none.")
            continue
        stress = big.max_stress_Pa / small.max_stress_Pa if small.max_stress_Pa > 0 else math.nan
        same = math.isfinite(stress) and abs(stress - 1.0) < 5e-3
        out.append(f"{describe(big)} takes {ratio_text(big.damage / small.damage)} times the "
                   f"damage of {describe(small)}, "
                   + ("at the same peak stress." if same else
                      f"at {ratio_text(stress)} times its peak stress."))
    return out


def _replayed(r: Report, span_days: float) -> list[str]:
    files = ", ".join(Path(f).name for f in r.input_files)
    out = [f"Buoy {r.buoy_id}" + (f", log {files}" if files else "") + ": "
           f"{_utc(r.time_start_ns)} to {_utc(r.time_end_ns)} ({duration_text(span_days)})."]
    s = r.sea_state
    if s is not None:
        def rng(x: Mapping[str, float], unit: str, fmt: str) -> str:
            if x["max"] - x["min"] < 0.05 * abs(x["mean"]):
                return f"{x['mean']:{fmt}} {unit}"
            return f"{x['mean']:{fmt}} {unit} ({x['min']:{fmt}} to {x['max']:{fmt}} {unit})"
        out.append(f"Sea state from the buoy's {s.reports:,d} wave reports: significant wave "
                   f"height {rng(s.hs_m, 'm', '.2g')}, peak period {rng(s.tp_s, 's', '.3g')}.")
    n = r.tension_counts
    measured, estimated = n.get("samples_measured"), n.get("samples_estimated")
    if measured is not None and estimated is not None:
        if measured and not estimated:
            src = f"the load cell ({measured:,d} samples)"
        elif estimated and not measured:
            src = (f"the {r.motion_sensor or 'motion'} estimate of tension ({estimated:,d} "
                   "samples, no load cell)")
        elif measured or estimated:
            src = (f"the load cell ({measured:,d} samples) and the "
                   f"{r.motion_sensor or 'motion'} estimate where it was missing "
                   f"({estimated:,d} samples)")
        else:
            src = "nothing: no load sample"
        out.append(f"Fatigue load from {src}.")
    t = r.tension
    if math.isfinite(t["max"]):
        line = f"Tension: mean {tension_text(t['mean'])}, peak {tension_text(t['max'])}"
        if r.breaking_load_N:
            line += (f" ({t['max'] / r.breaking_load_N:.0%} of the "
                     f"{tension_text(r.breaking_load_N)} breaking load)")
        out.append(line + ".")
    for problem in r.load_problems:
        out.append(f"Load: {problem}.")  # a gap in the load chain, not always "no load"
    return out


def _warnings(r: Report) -> list[str]:
    n, out = r.tension_counts, []
    above = n.get("samples_above_break", 0)
    if above:
        est = n.get("samples_estimate_above_break", 0)
        out.append(f"{above:,d} load samples lie above the "
                   + (f"{tension_text(r.breaking_load_N)} " if r.breaking_load_N else "")
                   + "breaking load" + (f" ({est:,d} of them estimates)" if est else "")
                   + ": the line would have parted, or the sensor is wrong; the damage counted "
                   "from them is not meaningful.")
    elif r.breaking_load_N and r.tension["max"] > r.breaking_load_N:
        out.append(f"The peak tension {tension_text(r.tension['max'])} exceeds the "
                   f"{tension_text(r.breaking_load_N)} breaking load.")
    clamped = n.get("samples_estimate_clamped", 0)
    if clamped:
        out.append(f"{clamped:,d} estimated load samples came from motion outside the "
                   "estimator's table and were held at its edge: the true loads there were "
                   "probably higher than counted.")
    return out


def _names(comps: list[Component]) -> str:
    names = [c.name for c in comps]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _next_steps(r: Report) -> list[str]:
    comps = list(r.components.values())
    design_days = (r.design_life_years or 0.0) * DAYS_PER_YEAR
    failed = [c for c in comps if c.damage >= 1.0]
    short = [c for c in comps if c.damage < 1.0 and design_days
             and c.remaining_life_days < design_days]
    out = []
    if failed:
        out.append("Treat " + _names(failed) + " as failed: inspect "
                   + ("it" if len(failed) == 1 else "them")
                   + " (continuity, insulation) and plan the replacement.")
    if short:
        out.append("Expect " + _names(short) + " to fail before the "
                   "design life if such loads continue: reduce the load or change the part.")
    if failed or short:
        for c in comps:  # the first of each kind is the reference (the as-built part)
            ref = next(x for x in comps if x.kind == c.kind)
            best = min((x for x in comps if x.kind == c.kind), key=lambda x: x.damage)
            if c is ref and best is not ref and best.damage < ref.damage:
                gain = ("no damage at all" if best.damage <= 0 else
                        f"{ratio_text(ref.damage / best.damage)} times less damage than "
                        f"{describe(ref)}")
                out.append(f"Of the configurations compared, {describe(best)} takes {gain}.")
    if r.tension_counts.get("samples_above_break"):
        out.append("Check the load cell's calibration and the line itself before trusting "
                   "the damage figures.")
    if r.tension_counts.get("samples_estimated"):
        out.append("Part of the load is a motion estimate: fit a load cell (or calibrate the "
                   "estimator against one) to narrow the damage band.")
    if not out:
        out.append("No action needed: no component failed"
                   + (" and every one outlasts its design life at this loading."
                      if design_days else "."))
    return out


def findings(r: Report) -> Findings:
    """The report's finding in sentences (see the module docstring)."""
    span_days = max(r.time_end_ns - r.time_start_ns, 0) / 86400e9
    return Findings(
        replayed=_replayed(r, span_days),
        verdicts=[_verdict(c, r, span_days) for c in r.components.values()],
        comparisons=_comparisons(r),
        warnings=_warnings(r),
        next_steps=_next_steps(r),
    )


def findings_text(f: Findings, indent: str = "  ") -> str:
    """The findings as terminal lines: a heading per group, one sentence per line."""
    lines = []
    for heading, sentences in f.sections():
        lines.append(f"{heading}:")
        lines += [f"{indent}{s}" for s in sentences]
    return "\n".join(lines)
