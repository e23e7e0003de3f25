"""Every configuration error in one run (operator test: ``buoymon check-config`` stopped at the
first, so a file with several typos took several runs). Each section is parsed on its own and
its errors gathered; a struct section gathers the errors of all its keys."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from monitor.config import LoadConfig, parse_config
from monitor.schema import ConfigError, ConfigErrors, parse_struct

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}

# mistakes in eight sections: typos of keys and a section, values out of range or choice
BAD = """\
[buoy]
id = "vaps"

[[component]]
name = "c1"
lay = "up"

[[component]]
name = "c2"
lay = "right"
scff = 2.0

[fatigue]
rate_window_s = -5

[load]
source = "measurd"
stale_afer_s = 4.0

[zenoh]
mode = "router"
listn = ["tcp/127.0.0.1:7447"]

[metrics]
port = 70000

[[alerts.rule]]
name = "x"
kind = "nope"

[recrod]
dir = "x"
"""

EXPECTED = [
    "config error: [recrod]: unknown section (did you mean 'record'?); expected one of "
    "['alerts', 'bridge', 'buoy', 'cable', 'component', 'fatigue', 'forecast', 'health', "
    "'load', 'metrics', 'mooring', 'ordering', 'record', 'rerun', 'source', 'state', "
    "'validate', 'zenoh']",
    "config error: load.source = 'measurd': must be one of ['auto', 'measured', 'estimated']",
    "config error: load.stale_afer_s = 4.0: unknown key (did you mean 'stale_after_s'?); "
    "expected one of ['breaking_load_N', 'motion_rate_hz', 'motion_sensor', 'slack_limit_N', "
    "'source', 'stale_after_s']",
    "config error: component[0].lay = 'up': must be one of ['left', 'right']",
    "config error: component[1].scff = 2.0: unknown key (did you mean 'scf'?); expected one of "
    "['bend_angle_deg', 'bend_gauge_length_m', 'bend_radius_m', 'derating', 'dff', "
    "'hysteresis_Pa', 'kind', 'lay', 'location', 'mean_stress', 'name', 'scf', 'sn_curve', "
    "'ultimate_Pa']",
    "config error: fatigue.rate_window_s = -5: must be a finite number > 0 and <= 1e+09",
    "config error: alerts.rule[0].kind = 'nope': unknown rule kind; expected one of "
    "['conductor_stress', 'conductor_yield', 'damage_fraction', 'damage_rate', "
    "'model_residual', 'rejected_rate', 'remaining_life', 'slack_snap', 'stale', "
    "'tension_high']",
    "config error: zenoh.mode = 'router': must be one of ['peer', 'client']",
    "config error: zenoh.listn = ['tcp/127.0.0.1:7447']: unknown key (did you mean 'listen'?); "
    "expected one of ['auth', 'connect', 'listen', 'mode', 'multicast_scouting', "
    "'status_interval_s', 'tls']",
    "config error: metrics.port = 70000: must be an integer port 0..65535 (0: any free)",
]


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "monitor.cli", *args], env=ENV,
                          capture_output=True, text=True, timeout=120)


def test_check_config_names_every_mistake_in_one_run(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(BAD)
    out = _cli("check-config", str(bad))
    assert out.returncode == 2
    assert out.stdout == ""
    assert out.stderr.splitlines() == EXPECTED + [f"{bad}: {len(EXPECTED)} errors"]


def test_one_mistake_reads_as_before(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[buoy]\nid = "vaps"\n[[component]]\nname = "c1"\nlay = "up"\n')
    out = _cli("check-config", str(bad))
    assert (out.returncode, out.stderr) == (2, EXPECTED[3] + "\n")


@pytest.mark.integration  # starts the daemon's process (it stops at the configuration)
def test_run_lists_every_mistake_before_it_starts(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(BAD)
    out = _cli("run", "--config", str(bad))
    assert out.returncode == 2
    for line in EXPECTED:
        assert line in out.stderr


def test_a_struct_section_gathers_all_its_keys_then_checks_across_them():
    with pytest.raises(ConfigErrors) as exc:
        parse_struct(LoadConfig, {"source": "x", "breaking_load_N": -1, "slack_limit": 1}, "load")
    assert [str(e) for e in exc.value.errors] == [
        "config error: load.source = 'x': must be one of ['auto', 'measured', 'estimated']",
        "config error: load.breaking_load_N = -1: must be a finite number > 0",
        "config error: load.slack_limit = 1: unknown key (did you mean 'slack_limit_N'?); expected "
        "one of ['breaking_load_N', 'motion_rate_hz', 'motion_sensor', 'slack_limit_N', "
        "'source', 'stale_after_s']"]
    # the check across keys (LoadConfig.check) runs once the keys are valid: one error
    with pytest.raises(ConfigError) as one:
        parse_struct(LoadConfig, {"slack_limit_N": 5e4}, "load")
    assert not isinstance(one.value, ConfigErrors)
    assert str(one.value) == ("config error: load.slack_limit_N = 50000.0: must be < "
                              "breaking_load_N (45000)")


def test_validate_waits_for_the_sections_its_defaults_derive_from():
    """[validate]'s defaults come from [load] and [mooring]: with [load] bad, only [load] is
    named (a [validate] error is found on the next run, not guessed from wrong defaults)."""
    doc = {"buoy": {"id": "vaps"}, "component": [{"name": "c", "lay": "left"}],
           "load": {"source": "x"}, "validate": {"tension": {"stale_after_s": -1}}}
    with pytest.raises(ConfigError, match=r"^config error: load.source = 'x'.*\]$"):
        parse_config(doc)
    doc["load"] = {}
    with pytest.raises(ConfigError, match=r"^config error: validate.tension.stale_after_s = -1"):
        parse_config(doc)


def test_a_bridge_file_names_every_source_mistake(tmp_path):
    bridge = tmp_path / "bridge.toml"
    bridge.write_text(
        '[buoy]\nid = "b1"\n[bridge]\nconect = ["tcp/127.0.0.1:7447"]\n'
        '[[source]]\nname = "a"\nsensor = "tension"\ntransport = "serial"\n'
        'columns = { tension_N = 0 }\nbaud = 7\n'
        '[[source]]\nname = "b"\nsensor = "wind"\ntransport = "udp"\nport = 9000\n')
    out = _cli("check-config", str(bridge))
    assert out.returncode == 2
    lines = out.stderr.splitlines()
    assert lines[0].startswith("config error: bridge.conect = ['tcp/127.0.0.1:7447']: unknown "
                               "key (did you mean 'connect'?)")
    assert lines[1:] == [
        "config error: source[0].baud = 7: must be an integer >= 50 and <= 4000000",
        "config error: source[1].sensor = 'wind': must be one of "
        "['tension', 'motion', 'imu', 'gnss', 'waves']",
        f"{bridge}: 3 errors"]


def test_a_key_two_sections_read_is_named_once():
    """[buoy] id is read by the core and by the bridge inside the daemon: one line, not two."""
    doc = {"component": [{"name": "c", "lay": "left"}],
           "source": [{"name": "a", "sensor": "tension", "transport": "stdin",
                       "columns": {"tension_N": 0}}]}
    with pytest.raises(ConfigError) as exc:
        parse_config(doc)
    assert not isinstance(exc.value, ConfigErrors)
    assert str(exc.value) == "config error: buoy.id is missing"


@pytest.mark.parametrize("preset", [[], {}])
def test_a_mooring_preset_that_is_no_name_is_a_config_error_beside_the_others(preset):
    """`preset = []` crashed parsing (TypeError: unhashable type) and took the file's other
    errors with it: check-config printed a traceback, no config error."""
    doc = {"buoy": {"id": "b1"}, "component": [{"name": "c", "lay": "up"}],
           "mooring": {"preset": preset}}
    with pytest.raises(ConfigErrors) as exc:
        parse_config(doc)
    assert str(exc.value).splitlines() == [
        f"config error: mooring.preset = {preset!r}: must be one of ['vaps_seed004']",
        "config error: component[0].lay = 'up': must be one of ['left', 'right']"]


def test_an_alert_rule_kind_that_is_no_name_is_a_config_error_beside_the_others():
    """`kind = []` crashed parsing (TypeError: unhashable type) and took the other rules'
    errors with it."""
    doc = {"buoy": {"id": "b1"}, "component": [{"name": "c", "lay": "left"}],
           "alerts": {"rule": [{"name": "x", "kind": []}, {"name": "y", "kind": "nope"}]}}
    with pytest.raises(ConfigErrors) as exc:
        parse_config(doc)
    lines = str(exc.value).splitlines()
    assert [line.split(": unknown rule kind")[0] for line in lines] == [
        "config error: alerts.rule[0].kind = []", "config error: alerts.rule[1].kind = 'nope'"]


def test_every_mistake_within_one_mooring_cable_component_or_validate_table():
    """[mooring], [cable], each [[component]] and [validate] gathered the errors of their tables
    but stopped at the first bad value inside one: two typos in one component took two runs."""
    doc = {"buoy": {"id": "b1"},
           "mooring": {"segment": [{"name": "a", "length_m": -1, "weight_N_per_m": 1.0,
                                    "ea_N": 1e9, "diameter_m": 0.02},
                                   {"name": "b", "length_m": 30.0, "weight_N_per_m": "x",
                                    "ea_N": 1e9, "diameter_m": 0}],
                       "depth_m": 20.0, "span_m": -3, "bearing_deg": 400},
           "cable": {"helix_radius_m": -1, "twist": "loose", "twist_limit_deg": 5},
           "component": [{"name": "c", "lay": "up", "scf": 0, "dff": "two",
                          "mean_stress": "goodman", "bend_radius_m": 0.1, "scff": 1}],
           "validate": {"tension": {"tension_N": {"min": "low", "spike_fail": -1},
                                    "stale_after_s": -2},
                        "imu": {"accel_x_mps2": {"flat_fail_s": -5}}, "wind": {}}}
    with pytest.raises(ConfigErrors) as exc:
        parse_config(doc)
    lines = str(exc.value).splitlines()
    assert [line.split(":")[1].strip().split(" = ")[0] for line in lines] == [
        "mooring.segment[0].length_m", "mooring.segment[1].weight_N_per_m",
        "mooring.segment[1].diameter_m", "mooring.span_m", "mooring.bearing_deg",
        "cable.helix_radius_m", "cable.twist", "component[0].lay", "component[0].scf",
        "component[0].dff", "component[0].bend_radius_m", "component[0].mean_stress",
        "component[0].scff"]
    assert lines[2] == ("config error: mooring.segment[1].diameter_m = 0: must be a finite "
                        "number > 0")
    assert lines[-1].startswith("config error: component[0].scff = 1: unknown key (did you mean "
                                "'scf'?)")
    # mean_stress = "goodman" without ultimate_Pa is named once the values it reads are valid
    doc["component"] = [{"name": "c", "lay": "left", "mean_stress": "goodman"}]
    doc["mooring"] = {"preset": "vaps_seed004"}
    doc["cable"] = {}
    with pytest.raises(ConfigErrors) as exc:
        parse_config(doc)
    assert [line.split(" = ")[0] for line in str(exc.value).splitlines()] == [
        "config error: component[0].mean_stress", "config error: validate.wind",
        "config error: validate.tension.tension_N.min",
        "config error: validate.tension.tension_N.spike_fail",
        "config error: validate.tension.stale_after_s",
        "config error: validate.imu.accel_x_mps2.flat_fail_s"]


def test_a_check_across_keys_waits_for_the_values_it_reads():
    """A stand-in for a bad value is never checked against: span_m bad and depth_m deeper than
    the line: two errors, each about its own key, none made up from the stand-in."""
    doc = {"buoy": {"id": "b1"}, "component": [{"name": "c", "lay": "left"}],
           "mooring": {"segment": [{"name": "a", "length_m": 10.0, "weight_N_per_m": 1.0,
                                    "ea_N": 1e9, "diameter_m": 0.02}],
                       "depth_m": "deep", "span_m": 5.0}}
    with pytest.raises(ConfigError) as exc:
        parse_config(doc)
    assert str(exc.value) == "config error: mooring.depth_m = 'deep': must be a finite number > 0"
    doc["mooring"]["depth_m"] = 12.0
    with pytest.raises(ConfigError) as exc:
        parse_config(doc)
    assert str(exc.value) == ("config error: mooring.depth_m = 12.0: deeper than the line is long "
                              "(10 m)")
    # a bad kind or location names itself alone, not the keys its stand-in would want
    doc["mooring"]["depth_m"] = 5.0
    for component, why in (
            ({"name": "c", "lay": "left", "location": "terminaton", "bend_radius_m": 0.5,
              "bend_angle_deg": 10.0}, "location = 'terminaton': must be one of"),
            ({"name": "c", "kind": "axail", "area_m2": 1e-4}, "kind = 'axail': must be one of")):
        doc["component"] = [component]
        with pytest.raises(ConfigError) as exc:
            parse_config(doc)
        assert not isinstance(exc.value, ConfigErrors)
        assert str(exc.value).startswith(f"config error: component[0].{why}")
