"""Issue 7 on the integrated product: the demo storm raises the damage warning on the as-built
seed 004 cable and none on the opposite lay, with the shipped configuration's rules."""

import tomllib
from importlib import resources

import pytest

from replay.cmd_demo import AS_BUILT, OPPOSITE, STORM, demo_config
from replay.runner import replay_logs
from replay.simulate import SimConfig, simulate

pytestmark = pytest.mark.integration  # processes, servers or whole records: not in `make test-fast`

HOURS = 2.0  # the as-built lay passes 0.1 after about 1.5 h of the storm (seed 4)


def test_shipped_damage_rules_are_per_component_warning_and_critical():
    raw = tomllib.loads(resources.files("monitor").joinpath("vaps_seed004.toml").read_text())
    damage = {r["name"]: r for r in raw["alerts"]["rule"] if r["kind"] == "damage_fraction"}
    assert {n: (r["severity"], r["threshold"]) for n, r in damage.items()} == {
        "damage_warning": ("warning", 0.1), "damage_critical": ("critical", 0.5)}
    assert all("component" not in r for r in damage.values())  # one alert per component


@pytest.fixture(scope="module")
def storm_report(tmp_path_factory):
    path = tmp_path_factory.mktemp("storm") / "storm.mcap"
    simulate(SimConfig(hours=HOURS, hs_m=STORM["hs"], tp_s=STORM["tp"], seed=STORM["seed"],
                       load_model=STORM["load_model"]), path)
    return replay_logs(demo_config(), [path], show_progress=False).report


def _fired(report, rule, component):
    return [a for a in report["alerts"] if a["labels"]["rule"] == rule
            and a["labels"]["component"] == component and a["event"] == "fire"]


def test_demo_storm_warns_on_the_as_built_lay_only(storm_report):
    r = storm_report
    left, right = r["components"][AS_BUILT], r["components"][OPPOSITE]
    assert left["damage_committed"] > 0.1 > right["damage"]
    fired = _fired(r, "damage_warning", AS_BUILT)
    assert len(fired) == 1 and fired[0]["severity"] == "warning"
    # within the storm, after the first hour (the damage grows by ~0.07 per hour)
    assert r["time_start_ns"] + 3600e9 < fired[0]["at_ns"] <= r["time_end_ns"]
    assert _fired(r, "damage_warning", OPPOSITE) == []
    assert not [a for a in r["alerts"] if a["labels"]["component"] == OPPOSITE
                and a["labels"]["rule"].startswith("damage")]
    # 0.5 is not reached in two hours; it latches later in the 10 h storm (about 8 h)
    assert _fired(r, "damage_critical", AS_BUILT) == []


def test_warning_latches_and_is_resent_not_refired(storm_report):
    warn = [a for a in storm_report["alerts"] if a["labels"]["rule"] == "damage_warning"
            and a["labels"]["component"] == AS_BUILT]
    assert [a["event"] for a in warn].count("fire") == 1
    assert "clear" not in [a["event"] for a in warn]
