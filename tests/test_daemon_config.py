"""[zenoh], [state], [record], [health], [metrics]: defaults and one test per invalid-config case."""

import pytest

from monitor.daemon_config import (
    AuthConfig, HealthConfig, RecordConfig, StateConfig, TlsConfig, ZenohConfig,
    parse_daemon_sections,
)
from monitor.schema import parse_struct
from monitor.zenoh_io import session_config_dict


def test_defaults_are_a_loopback_only_peer():
    cfg = parse_daemon_sections({})
    assert cfg.zenoh.mode == "peer"
    assert cfg.zenoh.listen == ("tcp/127.0.0.1:7447",)
    conf = session_config_dict(cfg.zenoh)
    assert conf["listen"]["endpoints"] == ["tcp/127.0.0.1:7447"]
    assert conf["connect"]["endpoints"] == []
    assert conf["scouting"]["multicast"]["enabled"] is False
    assert conf["scouting"]["gossip"]["enabled"] is False
    assert conf["timestamping"]["enabled"] is True
    assert "transport" not in conf
    assert cfg.state.checkpoint_interval_s == 10.0
    assert cfg.record.enabled is False and cfg.record.rotate_s == 3600.0
    assert cfg.health.data_age_timeout_s["tension"] == 5.0
    # live (wall-clock) rules on, metrics on loopback
    assert cfg.health.live_rules and cfg.health.fatigue_blind_timeout_s == 60.0
    assert cfg.health.clock_skew_max_s == 600.0 and cfg.health.required_streams == ()
    assert (cfg.metrics.enabled, cfg.metrics.listen, cfg.metrics.port) == (True, "127.0.0.1", 9464)


def test_client_mode_tls_and_auth_reach_the_zenoh_config():
    zc = parse_struct(ZenohConfig, {
        "mode": "client", "connect": ["tls/shore.example:7447"],
        "tls": {"root_ca_certificate": "/ca.pem", "connect_certificate": "/c.pem",
                "connect_private_key": "/k.pem", "enable_mtls": True},
        "auth": {"user": "buoy", "password": "pw"},
    }, "zenoh")
    assert zc.listen == ()  # a client listens on nothing unless told to
    conf = session_config_dict(zc)
    assert conf["mode"] == "client"
    assert conf["connect"]["endpoints"] == ["tls/shore.example:7447"]
    assert conf["transport"]["link"]["tls"] == {
        "root_ca_certificate": "/ca.pem", "connect_certificate": "/c.pem",
        "connect_private_key": "/k.pem", "enable_mtls": True}
    assert conf["transport"]["auth"]["usrpwd"] == {"user": "buoy", "password": "pw"}


def test_sections_parse_given_values():
    cfg = parse_daemon_sections({
        "state": {"path": "/tmp/s.sqlite", "checkpoint_interval_s": 2},
        "record": {"dir": "/tmp/rec", "rotate_s": 600, "flush_interval_s": 1.5},
        "health": {"data_age_timeout_s": {"tension": 2.5}},
        "zenoh": {"status_interval_s": 0.5},
    })
    assert cfg.state == StateConfig("/tmp/s.sqlite", 2.0)
    assert cfg.record == RecordConfig(True, "/tmp/rec", 600.0, 1.5)  # a dir enables recording
    assert cfg.health.data_age_timeout_s["tension"] == 2.5
    assert cfg.health.data_age_timeout_s["imu"] == 5.0
    assert cfg.zenoh.status_interval_s == 0.5


@pytest.mark.parametrize("section, d, message", [
    ("zenoh", {"mode": "router"}, "zenoh.mode = 'router': must be one of"),
    ("zenoh", {"listen": "tcp/127.0.0.1:7447"}, "zenoh.listen = 'tcp/127.0.0.1:7447': must be a list"),
    ("zenoh", {"listen": ["127.0.0.1:7447"]}, "endpoint '127.0.0.1:7447' is not of the form"),
    ("zenoh", {"connect": [7447]}, "zenoh.connect = [7447]"),
    ("zenoh", {"mode": "client"}, "zenoh.connect = []: client mode needs at least one endpoint"),
    ("zenoh", {"multicast_scouting": "no"}, "zenoh.multicast_scouting = 'no': must be true or false"),
    ("zenoh", {"status_interval_s": 5}, "zenoh.status_interval_s = 5: must be a finite number > 0 and <= 1"),
    ("zenoh", {"status_interval_s": 0}, "zenoh.status_interval_s = 0: must be a finite number > 0"),
    ("zenoh", {"port": 7447}, "zenoh.port = 7447: unknown key"),
    ("zenoh", {"tls": {"listen_certificate": "/c.pem"}},
     "zenoh.tls.listen_private_key = None: listen_certificate and listen_private_key"),
    ("zenoh", {"tls": {"root_ca_certificate": ""}}, "zenoh.tls.root_ca_certificate = '': must be a non-empty"),
    ("zenoh", {"tls": {"enable_mtls": 1}}, "zenoh.tls.enable_mtls = 1: must be true or false"),
    ("zenoh", {"auth": {"user": "u"}}, "zenoh.auth.password = None: user and password"),
    ("zenoh", {"auth": {"token": "x"}}, "zenoh.auth.token = 'x': unknown key"),
    ("zenoh", "peer", "zenoh = 'peer': must be a table"),
    # check-config said ok; `buoymon run` failed at start ("invalid port value")
    ("zenoh", {"listen": ["tcp/127.0.0.1:99999"]},
     "zenoh.listen = ['tcp/127.0.0.1:99999']: endpoint 'tcp/127.0.0.1:99999': port 99999 is "
     "not in 0..65535"),
    ("zenoh", {"mode": "client", "connect": ["tcp/[::1]:70000#iface=lo"]},
     "endpoint 'tcp/[::1]:70000#iface=lo': port 70000 is not in 0..65535"),
    ("state", {"path": ""}, "state.path = '': must be a non-empty string"),
    ("state", {"checkpoint_interval_s": -1}, "state.checkpoint_interval_s = -1: must be a finite number > 0"),
    ("state", {"checkpoint_interval_s": float("nan")}, "state.checkpoint_interval_s = nan"),
    ("state", {"checkpoint_interval_s": True}, "state.checkpoint_interval_s = True"),
    ("record", {"dir": 3}, "record.dir = 3: must be a non-empty string"),
    ("record", {"rotate_s": 0}, "record.rotate_s = 0: must be a finite number > 0"),
    ("record", {"flush_interval_s": "5"}, "record.flush_interval_s = '5'"),
    ("record", {"enabled": "yes"}, "record.enabled = 'yes': must be true or false"),
    ("health", {"data_age_timeout_s": {"tension": 0}},
     "health.data_age_timeout_s.tension = 0: must be a finite number > 0"),
    ("health", {"data_age_timeout_s": {"sonar": 3}}, "health.data_age_timeout_s.sonar = 3: unknown key"),
    ("health", {"stale": 3}, "health.stale = 3: unknown key"),
    ("health", {"live_rules": "on"}, "health.live_rules = 'on': must be true or false"),
    ("health", {"required_streams": ["sonar"]}, "health.required_streams = ['sonar']: must be a list"),
    ("health", {"fatigue_blind_timeout_s": 0}, "health.fatigue_blind_timeout_s = 0: must be"),
    ("health", {"clock_skew_max_s": -1}, "health.clock_skew_max_s = -1: must be"),
    ("health", {"time_restart_min_s": "1"}, "health.time_restart_min_s = '1': must be"),
    ("health", {"hold_s": float("inf")}, "health.hold_s = inf: must be a finite number > 0"),
    ("metrics", {"port": 70000}, "metrics.port = 70000: must be an integer port"),
    ("metrics", {"port": "9464"}, "metrics.port = '9464': must be an integer port"),
    ("metrics", {"listen": ""}, "metrics.listen = '': must be a non-empty host"),
    ("metrics", {"enabled": 0}, "metrics.enabled = 0: must be true or false"),
    ("metrics", {"path": "/m"}, "metrics.path = '/m': unknown key"),
])
def test_invalid_config_names_key_and_value(section, d, message):
    with pytest.raises(ValueError) as exc:
        parse_daemon_sections({section: d})
    assert "config error: " in str(exc.value)
    assert message in str(exc.value)


def test_section_classes_parse_alone():
    assert parse_struct(TlsConfig, {}, "zenoh.tls") == TlsConfig()
    assert parse_struct(AuthConfig, {"dictionary_file": "/u.txt"}, "zenoh.auth"
                        ).dictionary_file == "/u.txt"
    assert parse_struct(HealthConfig, {}, "health").data_age_timeout_s["gnss"] == 10.0
