"""What-if reprocessing: replay an archive with configuration overrides and compare.

Overrides are a partial configuration document merged into the baseline's (``--config`` or the
default), then re-validated by :func:`monitor.config.parse_config`, so a bad override is a
ConfigError naming the key. Two ways to write them, with the same meaning:

* a TOML file (``--whatif FILE.toml``) shaped like the configuration file, holding only what
  changes::

      [cable]
      helix_radius_m = 0.0115          # a larger helix

      [[component]]
      name = "conductor"               # matched by name: only the keys given change
      lay = "right"                    # the other conductor lay
      sn_curve = { stress_range_Pa = [3.0e7, 5.0e7], cycles = [1.0e7, 1.0e4] }

* ``--set KEY=VALUE`` (repeatable), a dotted key into the same document. A component is named
  by its ``name``: ``--set component.conductor.lay=right``, ``--set cable.helix_radius_m=0.0115``,
  ``--set component.conductor.derating=2``. VALUE is read as a TOML value (``2``, ``1.5e7``,
  ``true``, ``[1, 2]``, ``"text"``); anything that is not TOML is taken as a string (``right``).

Merge rules: tables merge key by key; an array of tables whose items all have a ``name``
(``[[component]]``) merges item by item by name, and an item with a new name is added; any
other value (numbers, strings, other arrays) is replaced.

:func:`run_whatif` replays the archive twice (baseline and what-if, all jobs in one pool or
cluster run) and :func:`compare` tabulates damage and remaining life per buoy and component.
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from monitor.config import Config, ConfigError, parse_config
from replay.fleet import BuoyArchive, make_jobs, run_jobs

WHATIF_REPORT_VERSION = 1


@dataclass(frozen=True)
class WhatIf:
    """A named set of overrides (a partial configuration document)."""

    name: str
    overrides: Mapping[str, Any]
    # components a --set names: one key cannot describe a new component, so a name the
    # baseline lacks is a typo, refused rather than added beside the one meant
    set_components: tuple[str, ...] = ()


def parse_value(text: str) -> Any:
    """A ``--set`` value: a TOML value if it parses as one, else the text itself."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_set(expr: str) -> dict[str, Any]:
    """``"component.conductor.lay=right"`` -> ``{"component": [{"name": "conductor", "lay":
    "right"}]}``: the partial document one ``--set`` stands for."""
    key, sep, value = expr.partition("=")
    parts = key.strip().split(".")
    if not sep or not all(p.strip() for p in parts):
        raise ConfigError(f"config error: --set {expr!r}: expected KEY=VALUE with a dotted KEY, "
                          "e.g. component.conductor.lay=right")
    parts = [p.strip() for p in parts]
    if parts[0] == "component":
        if len(parts) != 3:
            raise ConfigError(f"config error: --set {expr!r}: a component key is "
                              "component.<name>.<key>, e.g. component.conductor.lay=right")
        return {"component": [{"name": parts[1], parts[2]: parse_value(value.strip())}]}
    doc: Any = parse_value(value.strip())
    for p in reversed(parts):
        doc = {p: doc}
    return doc


def _named_tables(items: Any) -> bool:
    return isinstance(items, list) and all(isinstance(i, Mapping) and "name" in i for i in items)


def merge(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``overrides`` merged in (see the module doc); neither input is changed."""
    out = copy.deepcopy(dict(base))
    for key, new in overrides.items():
        old = out.get(key)
        if isinstance(old, Mapping) and isinstance(new, Mapping):
            out[key] = merge(old, new)
        elif old is not None and _named_tables(old) and _named_tables(new):
            items = [dict(i) for i in old]
            index = {i["name"]: k for k, i in enumerate(items)}
            for item in new:
                if item["name"] in index:
                    k = index[item["name"]]
                    items[k] = merge(items[k], item)
                else:
                    index[item["name"]] = len(items)
                    items.append(copy.deepcopy(dict(item)))
            out[key] = items
        else:
            out[key] = copy.deepcopy(new)
    return out


def load_whatif(path: str | Path | None = None, sets: Sequence[str] = ()) -> WhatIf:
    """The what-if from a TOML file and/or ``--set`` expressions (applied after the file)."""
    overrides: dict[str, Any] = {}
    name = "whatif"
    if path is not None:
        path = Path(path)
        try:
            overrides = tomllib.loads(path.read_text())
        except FileNotFoundError:
            raise ConfigError(f"config error: what-if file {str(path)!r} not found") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"config error: {path}: not valid TOML: {exc}") from None
        name = path.stem
    set_components: list[str] = []
    for expr in sets:
        one = parse_set(expr)
        set_components += [c["name"] for c in one.get("component", [])]
        overrides = merge(overrides, one)
    if not overrides:
        raise ConfigError("config error: the what-if changes nothing (empty file, no --set)")
    return WhatIf(name, overrides, tuple(set_components))


def apply_whatif(config: Config, whatif: WhatIf) -> Config:
    """The baseline configuration with the what-if's overrides, validated, including the
    cable and S-N curve the models build from it (so a bad override fails before any replay)."""
    from monitor.components import build_cable, build_sn_curve
    from monitor.schema import did_you_mean

    known = [c.name for c in config.components]
    for name in whatif.set_components:
        if name not in known:
            raise ConfigError(f"config error: --set component.{name}: no component {name!r} in "
                              f"the configuration{did_you_mean(name, known)}; expected one of "
                              f"{known} (a new component needs a --whatif file)")
    alt = parse_config(merge(config.raw, whatif.overrides),
                       source=f"{config.source} + what-if {whatif.name}")
    try:
        build_cable(alt)
        for comp in alt.components:
            build_sn_curve(comp)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    return alt


def run_whatif(archives: Sequence[BuoyArchive], config: Config, whatif: WhatIf, *,
               workers: int = 1, cluster: str | None = None,
               on_done: Callable[[str], None] | None = None
               ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Replay the archive with the baseline and with the what-if configuration (one run of
    2 x buoys jobs); return (baseline reports, what-if reports), in the order of ``archives``."""
    alt = apply_whatif(config, whatif)
    jobs = make_jobs(archives, config) + make_jobs(archives, alt)
    reports = run_jobs(jobs, workers=workers, cluster=cluster, on_done=on_done)
    return reports[:len(archives)], reports[len(archives):]


def _ratio(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or a == 0:
        return None
    return b / a


def compare(baseline: Sequence[Mapping[str, Any]], whatif: Sequence[Mapping[str, Any]],
            name: str = "whatif") -> dict[str, Any]:
    """Per buoy and component: damage, max stress and remaining life, baseline vs what-if.

    ``damage_ratio`` = what-if / baseline damage (None when the baseline has none). A component
    present on one side only has None on the other.
    """
    alt = {r["buoy_id"]: r for r in whatif}
    rows = []
    for base in baseline:
        other = alt.get(base["buoy_id"], {"components": {}})
        names = list(base["components"]) + [n for n in other["components"]
                                            if n not in base["components"]]
        for comp in names:
            b = base["components"].get(comp, {})
            w = other["components"].get(comp, {})
            rows.append({
                "buoy_id": base["buoy_id"],
                "component": comp,
                "damage_baseline": b.get("damage"),
                "damage_whatif": w.get("damage"),
                "damage_ratio": _ratio(b.get("damage"), w.get("damage")),
                "max_stress_Pa_baseline": b.get("max_stress_Pa"),
                "max_stress_Pa_whatif": w.get("max_stress_Pa"),
                "remaining_life_days_baseline": b.get("remaining_life_days"),
                "remaining_life_days_whatif": w.get("remaining_life_days"),
            })
    return {"whatif_report_version": WHATIF_REPORT_VERSION, "whatif": name, "rows": rows}


def _fmt(x: float | None, spec: str) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def comparison_text(table: Mapping[str, Any]) -> str:
    lines = [f"what-if {table['whatif']!r} vs baseline",
             f"  {'buoy':16s} {'component':20s} {'damage base':>12s} {'damage what-if':>14s} "
             f"{'ratio':>8s} {'life base':>11s} {'life what-if':>12s}"]
    for r in table["rows"]:
        lines.append(
            f"  {r['buoy_id']:16s} {r['component']:20s} {_fmt(r['damage_baseline'], '.3e'):>12s} "
            f"{_fmt(r['damage_whatif'], '.3e'):>14s} {_fmt(r['damage_ratio'], '.3g'):>8s} "
            f"{_fmt(r['remaining_life_days_baseline'], '.3g'):>9s} d "
            f"{_fmt(r['remaining_life_days_whatif'], '.3g'):>10s} d")
    return "\n".join(lines)
