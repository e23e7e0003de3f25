"""One fatigue component: load -> stress -> streaming rainflow -> Miner damage.

A thin adapter over ``models.helix`` and ``models.fatigue`` so the pipeline sees one small
interface per ``[[component]]``: conductors get the helix stress of their lay
(``models.helix.conductor_stress``; at ``location = "termination"`` the stress where the
moulding fixes them, ``models.termination``), axial members ``tension / area_m2``.

Yield: a conductor whose hot-spot stress (``scf`` x stress) exceeds the copper's tensile yield
(``HelixCable.conductor_yield_Pa``) is outside the elastic helix model and the S-N curve, so
its damage is underestimated; such samples are counted (``samples_beyond_yield``) for the
report, the status and the ``conductor_yield`` alert rule.

Damage bookkeeping is independent of block sizes: cycles closed by the rainflow are held as
*pending* until the alert tick that contains their closing sample ends, and then committed to
the Miner accumulator dated at the tick end. Tick ends are a fixed sensor-time grid, so the
committed damage (a sequential sum in closure order) and the damage rate (bucketed by those
dates) are the same for any split of the data. Pending cycles (at most one tick's worth) are
part of the saved state; figures read between ticks include them.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from typing import Any, Mapping, Sequence

import numpy as np

from models import fatigue, helix, termination
from monitor.config import ComponentConfig, Config, FatigueConfig
from monitor.schema import ConfigError, check_keys


def build_sn_curve(cfg: ComponentConfig) -> Any:
    """The component's S-N curve with its derating, SCF, DFF and mean-stress rule applied.

    ``sn_curve`` names an ``SNCurve`` constructor, with colon-separated arguments for those
    that take them: ``"vaps_copper"``, ``"dnv_chain_studless"``, ``"dnv_rp_c203:D:seawater_cp"``.
    """
    sn = cfg.sn_curve
    if sn.preset is not None:
        name, *args = sn.preset.split(":")
        factory = getattr(fatigue.SNCurve, name, None) if not name.startswith("_") else None
        if factory is None or name in ("tabulated", "basquin", "multi_slope", "from_dict"):
            raise ConfigError(f"config error: component {cfg.name!r}: sn_curve = {sn.preset!r}: "
                              "not an SNCurve preset (vaps_copper, dnv_rp_c203:<detail>:<env>, "
                              "dnv_chain_studless)")
        try:
            curve = factory(*args)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"config error: component {cfg.name!r}: sn_curve = "
                              f"{sn.preset!r}: {exc}") from None
    else:
        try:
            curve = fatigue.SNCurve.tabulated(np.array(sn.stress_range_Pa) / 1e6, sn.cycles)
        except ValueError as exc:
            raise ConfigError(f"config error: component {cfg.name!r}: sn_curve table: {exc}"
                              ) from None
    try:
        return curve.with_factors(derating=cfg.derating, scf=cfg.scf, dff=cfg.dff,
                                  mean_correction=cfg.mean_stress, ultimate_Pa=cfg.ultimate_Pa)
    except ValueError as exc:
        raise ConfigError(f"config error: component {cfg.name!r}: {exc}") from None


def endurance_stress_Pa(cfg: ComponentConfig, curve: Any) -> float | None:
    """Conductor stress at which the derated curve's endurance is reached (alert threshold)."""
    if cfg.kind != "conductor":
        return None
    if curve.endurance_MPa is None:
        return float(curve.stress_range_at(1e7))
    return float(curve.endurance_MPa * 1e6 / (curve.scf * curve.derating))


def yield_stress_Pa(cfg: ComponentConfig, cable: Any) -> float | None:
    """Nominal conductor stress at which the hot spot (``scf`` x stress) reaches the conductor's
    yield; None for non-conductors and conductors with no yield stress (inf)."""
    if cfg.kind != "conductor" or not math.isfinite(cable.conductor_yield_Pa):
        return None
    return float(cable.conductor_yield_Pa / cfg.scf)


def build_bend(cfg: ComponentConfig) -> Any:
    """The termination bend of a ``location = "termination"`` component with its bend
    configured, else None (no bend strain: the free span's stress)."""
    if cfg.location != "termination" or cfg.bend_radius_m is None:
        return None
    return termination.TerminationBend(cfg.bend_radius_m, math.radians(cfg.bend_angle_deg),
                                       cfg.bend_gauge_length_m)


def build_cable(config: Config) -> Any:
    factory = getattr(helix.HelixCable, config.cable.preset, None)
    if factory is None:
        raise ConfigError(f"config error: cable.preset = {config.cable.preset!r}: "
                          "not a models.helix.HelixCable preset")
    base = factory()
    # a misspelt key: name it and the nearest field, not a Python signature
    check_keys("cable", config.cable.overrides, [f.name for f in dataclasses.fields(base)])
    try:
        return dataclasses.replace(base, **config.cable.overrides)
    except (TypeError, ValueError) as exc:  # a value the model refuses
        raise ConfigError(f"config error: cable: {exc}") from None


_EMPTY = np.zeros(0)


@dataclasses.dataclass(frozen=True)
class TickRun:
    """What :meth:`Component.run_ticks` did: the closed cycles (ranges, means, counts) in
    closure order, and per tick (damage, damage_committed, damage rate per day, remaining
    life in days) at its end, if asked for: ``columns``, a float64 array of each over the
    ticks, and ``figures``, the same as a tuple of floats per tick (made when first read:
    the pipeline's alert batch reads the columns)."""

    cycles: tuple[np.ndarray, np.ndarray, np.ndarray]
    columns: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]

    @functools.cached_property
    def figures(self) -> list[tuple[float, float, float, float]]:
        return list(zip(*(c.tolist() for c in self.columns)))


class Component:
    """Stress, rainflow and damage of one ``[[component]]``."""

    def __init__(self, cfg: ComponentConfig, cable: Any, fcfg: FatigueConfig,
                 state: Mapping[str, Any] | None = None) -> None:
        self.name = cfg.name
        self.cfg = cfg
        self._cable = cable
        self._fcfg = fcfg
        self.sn_curve = build_sn_curve(cfg)
        self._bend = build_bend(cfg)
        self.yield_stress_Pa = yield_stress_Pa(cfg, cable)
        self.samples_beyond_yield = 0 if state is None else int(state.get("samples_beyond_yield", 0))
        if state is None:
            self.rainflow = fatigue.StreamingRainflow(hysteresis=cfg.hysteresis_Pa)
            self.miner = fatigue.MinerAccumulator(
                self.sn_curve, histogram_edges_Pa=np.array(fcfg.histogram_edges_Pa),
                rate_window_s=fcfg.rate_window_s, reference_cycles=fcfg.reference_cycles,
            )
            self._pending: list[np.ndarray] = [_EMPTY, _EMPTY, _EMPTY]
            self.max_stress_Pa = -math.inf
        else:
            self.rainflow = fatigue.StreamingRainflow.from_state(state["rainflow"])
            self.miner = fatigue.MinerAccumulator.from_state(state["miner"])
            self._pending = [np.array(v, dtype=np.float64) for v in state["pending"]]
            peak = state["max_stress_Pa"]
            self.max_stress_Pa = -math.inf if peak is None else float(peak)

    def stress(self, tension_N: np.ndarray, record: bool = True) -> np.ndarray:
        """Stress of the component under the load samples; records the peak and counts the
        samples beyond yield (``record=False``: samples seen before, or recorded later with
        :meth:`peak` and :meth:`record`)."""
        if self._bend is not None:
            stress = termination.termination_stress(tension_N, self._cable, self.cfg.lay, self._bend)
        elif self.cfg.kind == "conductor":
            stress = helix.conductor_stress(tension_N, self._cable, lay=self.cfg.lay)
        else:
            stress = tension_N / self.cfg.area_m2
        if record:
            self.record(*self.peak(stress))
        return stress

    def peak(self, stress_Pa: np.ndarray) -> tuple[float, int]:
        """The stress samples' peak (-inf if none) and how many exceed the yield stress
        (pure: nothing is recorded)."""
        if stress_Pa.shape[0] == 0:
            return -math.inf, 0
        peak = float(stress_Pa.max())
        limit = self.yield_stress_Pa
        if limit is not None and peak > limit:  # the peak is known: count only when needed
            return peak, int(np.count_nonzero(stress_Pa > limit))
        return peak, 0

    def record(self, peak_Pa: float, beyond_yield: int) -> None:
        """Record a :meth:`peak`."""
        self.max_stress_Pa = max(self.max_stress_Pa, peak_Pa)
        self.samples_beyond_yield += beyond_yield

    def feed(self, stress_Pa: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rainflow the next stress samples; returns the cycles they closed (kept pending)."""
        if stress_Pa.shape[0] == 0:
            return _EMPTY, _EMPTY, _EMPTY
        ranges, means, counts = self.rainflow.feed(stress_Pa)
        if ranges.shape[0]:
            # (in place: a component counting with this one shares the list)
            if self._pending[0].shape[0]:
                self._pending[:] = [np.concatenate([p, c])
                                    for p, c in zip(self._pending, (ranges, means, counts))]
            else:
                self._pending[:] = [ranges, means, counts]
        return ranges, means, counts

    def commit(self, tick_end_ns: int) -> None:
        """End of an alert tick: add the pending cycles to the Miner sum in one step."""
        ranges, means, counts = self._pending
        self.miner.add_cycles(ranges, means, counts, time_s=tick_end_ns / 1e9)
        self._pending[:] = [_EMPTY, _EMPTY, _EMPTY]

    def count_with(self, other: "Component") -> bool:
        """Share ``other``'s rainflow counter, Miner sum and pending cycles from now on if
        they count the same: the same configuration but for the name and the location, and
        the same bend or none (so the same stress of the same load), and the same counting
        state (the default conductor and its termination). Then feeding either one (``feed``,
        ``commit``, ``run_ticks``) counts for both and the other must not be fed; each
        keeps its own peak stress and samples beyond yield. Returns whether they share."""
        def counting(c: Component) -> tuple[Any, ...]:
            return (dataclasses.replace(c.cfg, name="", location=""), c._bend, c._cable,
                    c._fcfg, json.dumps([c.rainflow.state(), c.miner.state(),
                                         [p.tolist() for p in c._pending]]))
        if counting(self) != counting(other):
            return False
        self.rainflow, self.miner, self._pending = other.rainflow, other.miner, other._pending
        return True

    def run_ticks(self, stress_Pa: np.ndarray, stops: list[int],
                  ends_ns: Sequence[int] | np.ndarray, figures: bool = True) -> TickRun:
        """Whole alert ticks: tick ``k`` takes ``stress_Pa[stops[k - 1]:stops[k]]`` (from 0
        for the first) and ends at ``ends_ns[k]``, where its cycles (and those pending from
        earlier blocks, first) are committed. ``figures`` asks for each tick's figures.
        One compiled pass (``models.fatigue.commit_ticks``) when available, else the same
        feed/commit loop (the same bits)."""
        if not stops:
            return TickRun((_EMPTY,) * 3, (_EMPTY,) * 4)
        ranges, means, counts = self._pending
        run = fatigue.commit_ticks(self.rainflow, self.miner, stress_Pa, stops,
                                   np.asarray(ends_ns, np.int64) / 1e9, (ranges, means, counts),
                                   residue=figures)
        if run is not None:  # the compiled pass
            self._pending[:] = [_EMPTY, _EMPTY, _EMPTY]
            columns = ((run.damage, run.committed, run.rate_per_day, run.life_days) if figures
                       else (_EMPTY,) * 4)
            return TickRun((run.ranges, run.means, np.ones(run.ranges.shape[0])), columns)
        parts, out, start = [], [], 0
        for stop, end in zip(stops, ends_ns):
            if stop > start:
                parts.append(self.feed(stress_Pa[start:stop]))
            self.commit(end)
            if figures:
                f = self.figures()
                out.append((f["damage"], f["damage_committed"], f["damage_rate_per_day"],
                            f["remaining_life_days"]))
            start = stop
        cycles = tuple(np.concatenate(p) for p in zip(*parts)) if parts else (_EMPTY,) * 3
        columns = np.array(out, np.float64).reshape(-1, 4).T
        return TickRun(cycles, (columns[0], columns[1], columns[2], columns[3]))

    def _damage(self, ranges: np.ndarray, means: np.ndarray, counts: np.ndarray) -> float:
        """Damage of the pending cycles, each as the committed ones' (``damage_per_cycle``)."""
        if ranges.shape[0] == 0:
            return 0.0
        return float(np.sum(self.sn_curve.damage_per_cycle(ranges, means, counts)))

    def figures(self, counting: Mapping[str, float] | None = None) -> dict[str, float]:
        """damage (with pending cycles and the open residue as half cycles), committed, rate,
        life, cycles (:meth:`counting_figures`, or ``counting``: those of a component this
        one counts with), and its own peak stress and samples beyond yield."""
        return {
            **(self.counting_figures() if counting is None else counting),
            "max_stress_Pa": self.max_stress_Pa if math.isfinite(self.max_stress_Pa) else math.nan,
            "samples_beyond_yield": float(self.samples_beyond_yield),
        }

    def counting_figures(self) -> dict[str, float]:
        """damage (with pending cycles and the open residue as half cycles), committed, rate,
        life, cycles: the figures of the counting (shared by components counting together).

        ``damage_committed`` includes cycles closed since the last tick, computed fresh here
        and not accumulated, so reading figures never changes the state.
        """
        committed = self.miner.damage_committed + self._damage(*self._pending)
        damage = committed + self.miner.residue_damage(self.rainflow)
        rate = float(self.miner.damage_rate_per_day)
        return {
            "damage": damage,
            "damage_committed": committed,
            "damage_rate_per_day": rate,
            "remaining_life_days": fatigue.remaining_life_days(damage, rate),
            "cycles": float(self.miner.total_cycles) + (
                float(self._pending[2].sum()) if self._pending[2].shape[0] else 0.0),
        }

    def warm_up(self) -> None:
        """Run the compiled kernels once on throwaway objects (a process's first numba call
        costs a second or more), so a restarted daemon processes its first block promptly."""
        spare = Component(self.cfg, self._cable, self._fcfg)
        stress = spare.stress(np.array([1000.0, 2000.0, 1000.0, 3000.0, 500.0]))
        spare.feed(stress[:2])
        spare.commit(1)
        spare.run_ticks(stress, [3, 5], [2, 3])
        spare.figures()

    def state(self) -> dict[str, Any]:
        return {
            "rainflow": self.rainflow.state(),
            "miner": self.miner.state(),
            "pending": [p.tolist() for p in self._pending],
            "max_stress_Pa": self.max_stress_Pa if math.isfinite(self.max_stress_Pa) else None,
            "samples_beyond_yield": self.samples_beyond_yield,
        }
