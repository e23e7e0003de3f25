"""Configuration: the shipped seed 004 default, and one test per invalid-config case."""

import copy
import math
import re
import tomllib
from importlib import resources

import pytest

from monitor.cli import main
from monitor.config import ConfigError, config_with, default_config, load_config, parse_config


def shipped() -> dict:
    return tomllib.loads(resources.files("monitor").joinpath("vaps_seed004.toml").read_text())


def test_default_is_the_seed_004_mooring():
    c = default_config()
    assert c.buoy.id == "vaps"
    assert c.mooring.depth_m == 23.0 and c.mooring.length_m == 40.0
    assert c.mooring.preset == "vaps_seed004" and c.mooring.segments == ()
    assert c.mooring.span_m == 29.0 and c.load.motion_rate_hz == "auto"
    assert c.cable.preset == "vaps_biw" and not c.cable.overrides
    comp, term = c.components  # the free span and the termination moulding (issue 20)
    assert (comp.kind, comp.lay, comp.sn_curve.preset) == ("conductor", "left", "vaps_copper")
    assert comp.location == "free_span" and comp.bend_radius_m is None
    assert (term.kind, term.lay, term.location) == ("conductor", "left", "termination")
    # its bend is not shipped (an assumed one is beyond yield at rest: docs/CONDUCTOR.md)
    assert (term.bend_radius_m, term.bend_angle_deg, term.bend_gauge_length_m, term.scf) == (
        None, None, None, 1.0)
    assert c.load.source == "auto" and c.load.stale_after_s == 5.0
    assert c.alerts.eval_interval_s == 10.0
    # QC defaults derived from the line (monitor.config.qc_defaults): the 45 kN break load
    tension = c.validate["tension"].fields["tension_N"]
    assert tension.max_rate_per_s == 45_000.0 and (tension.suspect_min, tension.suspect_max) == (
        0.0, 45_000.0)
    assert c.load.motion_sensor == "auto" and c.load.breaking_load_N == 45_000.0
    # motion: +-23 m heave, +-40 m (line length) horizontal, sqrt(g d) = 15.02 m/s
    surge = c.validate["motion"].fields["surge_m"]
    assert (surge.min, surge.max) == (-40.0, 40.0)
    assert surge.max_rate_per_s == pytest.approx(math.sqrt(9.81 * 23.0))
    assert surge.suspect_max == pytest.approx(math.sqrt(40.0 ** 2 - 23.0 ** 2))  # watch circle
    assert c.validate["motion"].fields["heave_m"].max == 23.0
    assert c.validate["gnss"].location_range_max_m == 180.0
    assert c.validate["tension"].stale_after_s == c.load.stale_after_s
    assert c.validate["gnss"].stale_after_s == 60.0


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["component"][0].update(lay="up"),
     "config error: component[0].lay = 'up': must be one of ['left', 'right']"),
    (lambda d: d["component"][0].update(layy="left"),
     "config error: component[0].layy = 'left': unknown key (did you mean 'lay'?)"),
    (lambda d: d["component"][0].update(dff=-1),
     "config error: component[0].dff = -1: must be a finite number > 0"),
    (lambda d: d["component"][0].update(kind="axial"),
     "config error: component[0].area_m2 is missing"),
    (lambda d: d["component"][0].update(mean_stress="goodman"),
     "config error: component[0].mean_stress = 'goodman': needs ultimate_Pa"),
    (lambda d: d["component"].append(dict(d["component"][0])),
     "config error: component[2].name = 'conductor': duplicate name"),
    (lambda d: d.update(component=[]),
     "config error: component: at least one [[component]] is required"),
    (lambda d: d["load"].update(source="guess"),
     "config error: load.source = 'guess': must be one of ['auto', 'measured', 'estimated']"),
    (lambda d: d["load"].update(stale_after_s="5"),
     "config error: load.stale_after_s = '5': must be a finite number > 0 and <= 1e+09"),
    (lambda d: d["validate"]["tension"]["tension_N"].update(max=-6000.0),
     "config error: validate.tension.tension_N.max = -6000.0: must be > min (-5000)"),
    (lambda d: d["validate"].update(sonar={}),
     "config error: validate.sonar = {}: unknown sensor"),
    (lambda d: d["buoy"].update(id="a/b"),
     "config error: buoy.id = 'a/b': buoy id 'a/b' must be"),
    (lambda d: d["mooring"].update(depth_m=45.0),
     "config error: mooring.depth_m = 45.0: deeper than the line is long (40 m)"),
    (lambda d: d["mooring"].update(span_m=41.0),
     "config error: mooring.span_m = 41.0: must be shorter than the line (40 m)"),
    (lambda d: d["mooring"].update(preset="nope"),
     "config error: mooring.preset = 'nope': must be one of ['vaps_seed004']"),
    (lambda d: d["alerts"].update(eval_interval_s=0),
     "config error: alerts.eval_interval_s = 0: must be a finite number > 0 and <= 1e+09"),
    (lambda d: d["fatigue"].update(histogram_edges_Pa=[0.0, 2.0, 1.0]),
     "config error: fatigue.histogram_edges_Pa = [0.0, 2.0, 1.0]: must be strictly increasing"),
    (lambda d: d.update(zenohh={}),
     "config error: [zenohh]: unknown section (did you mean 'zenoh'?)"),
    (lambda d: d["component"][0].update(sn_curve={"stress_range_Pa": [2e8, 1e8], "cycles": [1e4]}),
     "config error: component[0].sn_curve.cycles = [10000.0]: must be a list of at least 2 "
     "finite numbers"),
    (lambda d: d["component"][0].update(sn_curve={"stress_range_Pa": [2e8, 1e8],
                                                  "cycles": [1e4, 1e5, 1e6]}),
     "config error: component[0].sn_curve = {'stress_range_Pa': [200000000.0, 100000000.0], "
     "'cycles': [10000.0, 100000.0,...: stress_range_Pa and cycles must be positive lists of "
     "the same length"),  # a long value is cut short
    (lambda d: d["ordering"].update(horizon_s=float("nan")),
     "config error: ordering.horizon_s = nan: must be a finite number"),
])
def test_invalid_values_name_the_key_and_value(mutate, message):
    data = copy.deepcopy(shipped())
    mutate(data)
    with pytest.raises(ConfigError) as exc:
        parse_config(data)
    assert str(exc.value).startswith(message), str(exc.value)


def test_explicit_segments_replace_the_preset():
    data = shipped()
    del data["mooring"]["preset"], data["mooring"]["span_m"]
    data["mooring"]["segment"] = [
        {"name": "chain", "length_m": 30.0, "weight_N_per_m": 400.0, "ea_N": 5e8, "diameter_m": 0.05},
    ]
    with pytest.raises(ConfigError, match="mooring.span_m is missing"):
        parse_config(data)
    data["mooring"]["span_m"] = 12.0
    c = parse_config(data)
    assert c.mooring.length_m == 30.0 and c.mooring.depth_m == 23.0
    assert c.mooring.segments[0].weight_N_per_m == 400.0
    data["mooring"]["preset"] = "vaps_seed004"
    with pytest.raises(ConfigError, match="mooring.preset = 'vaps_seed004': give either"):
        parse_config(data)


def test_config_with_adds_a_component_and_revalidates():
    c = default_config()
    both = config_with(c, component=[*c.raw["component"], {**c.raw["component"][0],
                                                            "name": "right", "lay": "right"}])
    assert [(x.name, x.lay) for x in both.components] == [
        ("conductor", "left"), ("conductor_termination", "left"), ("right", "right")]
    with pytest.raises(ConfigError, match="component\\[0\\].lay"):
        config_with(c, component=[{**c.raw["component"][0], "lay": 3}])


def test_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[buoy\nid = 1\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)
    # a folder given for the file was an OSError: exit status 1 with "[Errno 21] ..."
    with pytest.raises(ConfigError, match=rf"config error: {re.escape(str(tmp_path))}: cannot read "
                       r"\(Is a directory\)"):
        load_config(tmp_path)
    assert main(["check-config", str(tmp_path)]) == 2


def test_check_config_command(tmp_path, capsys):
    path = resources.files("monitor").joinpath("vaps_seed004.toml")
    assert main(["check-config", str(path)]) == 0
    out = capsys.readouterr().out
    assert "ok" in out and "conductor (conductor, left lay, vaps_copper)" in out
    assert "40 m line in 23 m of water" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace('lay = "left"', 'lay = "sideways"'))
    assert main(["check-config", str(bad)]) == 2
    assert "component[0].lay = 'sideways'" in capsys.readouterr().err
    # values only the models can judge are checked too
    bad.write_text(path.read_text().replace('sn_curve = "vaps_copper"', 'sn_curve = "brass"'))
    assert main(["check-config", str(bad)]) == 2
    assert "sn_curve = 'brass': not an SNCurve preset" in capsys.readouterr().err
    bad.write_text(path.read_text().replace('preset = "vaps_biw"', 'preset = "vaps_biw"\nhelix_radius = 0.01'))
    assert main(["check-config", str(bad)]) == 2
    assert ("config error: cable.helix_radius = 0.01: unknown key (did you mean 'helix_radius_m'?)"
            in capsys.readouterr().err)


def test_every_section_is_parsed_once_into_its_typed_object():
    c = config_with(default_config(), zenoh={"mode": "client", "connect": ["tcp/10.0.0.2:7447"]},
                    rerun={"envelope_s": 2.0}, health={"hold_s": 30.0})
    assert (c.daemon.zenoh.mode, c.daemon.zenoh.listen) == ("client", ())  # no listen default
    assert c.daemon.health.hold_s == 30.0 and c.daemon.state.checkpoint_interval_s == 10.0
    assert c.rerun.envelope_s == 2.0 and c.forecast.window_s == 1800.0 and c.bridge is None
    # the shipped rules: eight, the seventh a stale rule on the tension stream
    assert len(c.alerts.rules) == 8 and (c.alerts.rules[6].kind, c.alerts.rules[6].component) == (
        "stale", "tension")
    assert c.alerts.rules[4].params == {"threshold": 0.5, "breaking_strength_N": 45000.0,
                                        "deadband": 0.05, "on_delay_s": 0.0, "off_delay_s": 0.0}


@pytest.mark.parametrize("section, message", [
    # a misspelt section, a nested key, an alert rule's parameter, a bridge source's key
    ({"zenoh": {}, "forecst": {}},
     "config error: [forecst]: unknown section (did you mean 'forecast'?); expected one of "),
    ({"validate": {"tension": {"tension_N": {"suspect_mx": 1e4}}}},
     "config error: validate.tension.tension_N.suspect_mx = 10000.0: unknown key (did you mean "
     "'suspect_max'?)"),
    ({"zenoh": {"tls": {"root_ca_certifcate": "/ca.pem"}}},
     "config error: zenoh.tls.root_ca_certifcate = '/ca.pem': unknown key (did you mean "
     "'root_ca_certificate'?)"),
    ({"alerts": {"rule": [{"kind": "damage_fraction", "threshhold": 0.1}]}},
     "config error: alerts.rule[0].threshhold = 0.1: unknown key (did you mean 'threshold'?)"),
    ({"alerts": {"rule": [{"kind": "damage_fractoin", "threshold": 0.1}]}},
     "config error: alerts.rule[0].kind = 'damage_fractoin': unknown rule kind (did you mean "
     "'damage_fraction'?)"),
    ({"source": [{"name": "lc", "sensor": "tension", "transport": "stdin",
                  "columns": {"tension_N": 0}, "stal_s": 3.0}]},
     "config error: source[0].stal_s = 3.0: unknown key (did you mean 'stall_s'?)"),
    ({"rerun": {"envelope": 1.0}},
     "config error: rerun.envelope = 1.0: unknown key (did you mean 'envelope_s'?)"),
])
def test_misspelt_names_get_the_nearest_known_one(section, message):
    with pytest.raises(ConfigError) as exc:
        config_with(default_config(), **section)
    assert str(exc.value).startswith(message), str(exc.value)


def test_resend_interval_zero_means_never():
    """0 is the documented "never re-send" (monitor/alerts/config.py); negative is an error."""
    c = default_config()
    assert config_with(c, alerts={**c.raw["alerts"], "resend_interval_s": 0}).alerts.resend_interval_s == 0
    with pytest.raises(ConfigError, match="alerts.resend_interval_s = -1: must be a finite number >= 0"):
        config_with(c, alerts={**c.raw["alerts"], "resend_interval_s": -1})


@pytest.mark.parametrize("section, message", [
    ({"validate": {"tension": {"tension_N": {"flat_tolerance": -1.0}}}},
     "validate.tension.tension_N.flat_tolerance = -1.0: must be a number (inf allowed) >= 0"),
    ({"validate": {"motion": {"heave_m": {"suspect_min": 2.0, "suspect_max": 1.0}}}},
     "validate.motion.heave_m.suspect_max = 1.0: must be >= suspect_min"),
    ({"validate": {"gnss": {"location_range_max_m": "far"}}},
     "validate.gnss.location_range_max_m = 'far': must be a finite number >= 0"),
    ({"load": {"motion_sensor": "gps"}}, "load.motion_sensor = 'gps': must be one of"),
    ({"load": {"slack_limit_N": 50_000.0}}, "load.slack_limit_N = 50000.0: must be < breaking"),
])
def test_qc_keys_are_validated_with_key_and_value(section, message):
    from monitor.config import config_with

    with pytest.raises(ConfigError, match=re.escape(message)):
        config_with(default_config(), **section)



def test_the_readme_load_row_names_every_key_and_motion_sensor_choice():
    # the row listed motion_sensor = "imu" | "motion" while the default (and the shipped file)
    # is "auto", and left out breaking_load_N and slack_limit_N
    from pathlib import Path

    from monitor.config import LoadConfig

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    (row,) = [line for line in readme.splitlines() if line.startswith("| `[load]` |")]
    for key in LoadConfig.__struct_fields__:
        assert f"`{key}" in row, key
    c = default_config()
    with pytest.raises(ConfigError) as exc:
        config_with(c, load={**c.section("load"), "motion_sensor": "x"})
    accepted = re.search(r"must be one of \[(.*)\]", str(exc.value))[1]
    documented = row.split("`motion_sensor = ")[1].split("`")[0]
    assert sorted(re.findall(r'"(\w+)"', documented)) == sorted(re.findall(r"'(\w+)'", accepted))
