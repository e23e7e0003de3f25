"""What-if reprocessing: override syntax and merge rules, validation errors, the baseline vs
what-if comparison on a small archive, and the command line."""

import json

import numpy as np
import pytest

from monitor.blocks import SampleBlock
from monitor.cli import main
from monitor.config import ConfigError, config_with, default_config
from replay.fleet import discover, run_fleet
from replay.whatif import (WhatIf, apply_whatif, compare, comparison_text, load_whatif, merge,
                           parse_set, parse_value, run_whatif)
from replay.writer import LogWriter

T0 = 1_600_000_000 * 10**9
AMPS = {"calm": 900.0, "rough": 2600.0}


def measured_config():
    c = default_config()
    return config_with(c, load={**c.section("load"), "source": "measured"})


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    """2 buoys x 2 consecutive 2-minute files of 20 Hz tension."""
    root = tmp_path_factory.mktemp("whatif")
    rng = np.random.default_rng(7)
    for buoy, amp in AMPS.items():
        for part in range(2):
            with LogWriter(root / f"{buoy}_{part}.mcap") as w:
                for s in range(part * 120, (part + 1) * 120):
                    t = T0 + s * 10**9 + np.arange(20, dtype=np.int64) * 50_000_000
                    x = (t - T0) / 1e9
                    v = 5000 + amp * np.sin(2 * np.pi * x / 5.25) + rng.normal(0, 40, 20)
                    w.write_block(SampleBlock(buoy, "tension", t, {"tension_N": v}))
    return root


def test_parse_value_reads_toml_values_and_falls_back_to_text():
    assert parse_value("2") == 2 and parse_value("1.5e7") == 1.5e7
    assert parse_value("true") is True and parse_value("[1, 2]") == [1, 2]
    assert parse_value('"left"') == "left" and parse_value("right") == "right"


def test_parse_set_builds_the_partial_document():
    assert parse_set("component.conductor.lay=right") == {
        "component": [{"name": "conductor", "lay": "right"}]}
    assert parse_set("cable.helix_radius_m = 0.0115") == {"cable": {"helix_radius_m": 0.0115}}
    assert parse_set("fatigue.histogram_edges_Pa=[0, 1e6]") == {
        "fatigue": {"histogram_edges_Pa": [0, 1e6]}}
    for bad in ("lay", "cable..x=1", "=1", "component.lay=right"):
        with pytest.raises(ConfigError, match="--set"):
            parse_set(bad)


def test_merge_tables_by_key_components_by_name_and_replaces_the_rest():
    base = {"cable": {"preset": "vaps_biw"}, "fatigue": {"histogram_edges_Pa": [0, 1, 2]},
            "component": [{"name": "a", "lay": "left", "scf": 1.0}, {"name": "b", "lay": "left"}]}
    over = {"cable": {"pitch_m": 0.2}, "fatigue": {"histogram_edges_Pa": [0, 5]},
            "component": [{"name": "b", "lay": "right"}, {"name": "c", "lay": "right"}]}
    got = merge(base, over)
    assert got == {"cable": {"preset": "vaps_biw", "pitch_m": 0.2},
                   "fatigue": {"histogram_edges_Pa": [0, 5]},
                   "component": [{"name": "a", "lay": "left", "scf": 1.0},
                                 {"name": "b", "lay": "right"}, {"name": "c", "lay": "right"}]}
    assert base["component"][1] == {"name": "b", "lay": "left"}  # inputs untouched
    assert base["cable"] == {"preset": "vaps_biw"}


def test_load_whatif_from_file_then_sets(tmp_path):
    f = tmp_path / "bigger_helix.toml"
    f.write_text('[cable]\nhelix_radius_m = 0.0115\n\n[[component]]\nname = "conductor"\n'
                 'lay = "right"\n')
    w = load_whatif(f, ["component.conductor.derating=2"])
    assert w.name == "bigger_helix"
    assert w.overrides == {"cable": {"helix_radius_m": 0.0115},
                           "component": [{"name": "conductor", "lay": "right", "derating": 2}]}
    assert load_whatif(None, ["cable.pitch_m=0.2"]).name == "whatif"
    with pytest.raises(ConfigError, match="changes nothing"):
        load_whatif(None, [])
    with pytest.raises(ConfigError, match="not found"):
        load_whatif(tmp_path / "missing.toml")
    (tmp_path / "bad.toml").write_text("[cable\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_whatif(tmp_path / "bad.toml")


@pytest.mark.parametrize("expr, message", [
    ("component.conductor.lay=up", r"component\[0\]\.lay = 'up': must be one of"),
    ("cable.helix_radius_m=-0.01", r"cable\.helix_radius_m = -0\.01"),
    ("component.conductor.sn_curve=no_such_curve", r"sn_curve = 'no_such_curve'"),
    ("cable.no_such_field=1", r"config error: cable"),
    ("nonsense.key=1", r"unknown section"),
    # a misspelt component name was added as a new component, the one meant left unchanged
    ("component.conductr.lay=right", r"--set component\.conductr: no component 'conductr' in "
     r"the configuration \(did you mean 'conductor'\?\)"),
])
def test_bad_overrides_fail_before_any_replay_naming_the_key(expr, message):
    with pytest.raises(ConfigError, match=message):
        apply_whatif(measured_config(), load_whatif(None, [expr]))


def test_other_lay_whatif_equals_a_hand_built_config_and_lowers_damage(archive):
    archives = discover([archive])
    config = measured_config()
    base, alt = run_whatif(archives, config, WhatIf("right", parse_set(
        "component.conductor.lay=right")), workers=1)
    assert base == run_fleet(archives, config)
    by_hand = config_with(config, component=[{**config.raw["component"][0], "lay": "right"},
                                             *config.raw["component"][1:]])
    expected = run_fleet(archives, by_hand)
    assert [r["components"] for r in alt] == [r["components"] for r in expected]
    table = compare(base, alt, "right")
    rows = [r for r in table["rows"] if r["component"] == "conductor"]
    assert [r["buoy_id"] for r in rows] == ["calm", "rough"]
    for r, b, a in zip(rows, base, alt):
        assert r["damage_baseline"] == b["components"]["conductor"]["damage"]
        assert r["damage_whatif"] == a["components"]["conductor"]["damage"]
        assert r["damage_ratio"] == r["damage_whatif"] / r["damage_baseline"]
        # the seed's conclusion: the opposite lay has the lower conductor stress and damage
        assert r["damage_ratio"] < 0.5
        assert r["max_stress_Pa_whatif"] < r["max_stress_Pa_baseline"]
    text = comparison_text(table)
    assert "what-if 'right' vs baseline" in text and "rough" in text


def test_compare_lists_components_present_on_one_side():
    def rep(buoy, comps):
        return {"buoy_id": buoy, "components": {
            n: {"damage": d, "max_stress_Pa": 1.0, "remaining_life_days": None}
            for n, d in comps.items()}}
    table = compare([rep("b", {"x": 0.0, "y": 2.0})], [rep("b", {"y": 1.0, "z": 3.0})])
    rows = {r["component"]: r for r in table["rows"]}
    assert rows["x"]["damage_whatif"] is None and rows["x"]["damage_ratio"] is None
    assert rows["y"]["damage_ratio"] == 0.5
    assert rows["z"]["damage_baseline"] is None and rows["z"]["damage_whatif"] == 3.0
    assert "-" in comparison_text(table)


def test_cli_whatif_writes_comparison_and_both_report_sets(archive, tmp_path, capsys):
    from importlib import resources

    cfg = tmp_path / "measured.toml"
    cfg.write_text(resources.files("monitor").joinpath("vaps_seed004.toml").read_text()
                   .replace('source = "auto"', 'source = "measured"'))
    over = tmp_path / "derated.toml"
    over.write_text('[[component]]\nname = "conductor"\nderating = 2.0\n')
    out = tmp_path / "out"
    code = main(["replay", str(archive), "--config", str(cfg), "--whatif", str(over),
                 "--report-dir", str(out), "--report", str(tmp_path / "cmp.json"),
                 "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "what-if 'derated' vs baseline" in text
    table = json.loads((out / "comparison.json").read_text())
    assert json.loads((tmp_path / "cmp.json").read_text()) == table
    for r in table["rows"]:
        base = json.loads((out / "buoys" / f"{r['buoy_id']}.json").read_text())
        alt = json.loads((out / "whatif" / "buoys" / f"{r['buoy_id']}.json").read_text())
        assert r["damage_baseline"] == base["components"][r["component"]]["damage"]
        assert r["damage_whatif"] == alt["components"][r["component"]]["damage"]
        if r["component"] == "conductor":  # a weaker curve: more damage from the same stresses
            assert r["damage_ratio"] > 2
        else:  # the termination is not derated by the what-if
            assert r["damage_ratio"] == 1.0
    assert json.loads((out / "whatif" / "fleet.json").read_text())["buoys"][0]["buoy_id"] == "rough"
    # a bad override is a configuration error (exit 2), before anything is replayed
    assert main(["replay", str(archive), "--set", "component.conductor.lay=up"]) == 2
    assert "component[0].lay = 'up'" in capsys.readouterr().err
