"""Twist boundary condition of the helix model (issue 20, seed 004 section 2, App. 1 and 4).

The oracle is an independent trigonometric evaluation of Knapp's axial stress (App. 4,
sigma = E_i |cos a / cos a' (1 + e_c) - 1|, a' = atan((2 pi R + R theta) / (P (1 + e_c)))) with
the core strain and twist written out by hand for each boundary condition.
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from fatigue_oracles import axial_stress_oracle
from models.helix import HelixCable, conductor_stress, core_strain_twist, tension_for_stress

VAPS = HelixCable.vaps_biw()
AE = 42.1e-6 * 81.4e9  # App. 1: A_c E_c = 3.427e6 N
GC = 24.4e-6  # App. 1: rad / (N m)
BRIDLE = math.radians(75.0)  # section 2: the anchor bridle allows +/-75 deg
LENGTH = 40.0  # section 2: cable length buoy -> anchor


def _knapp(e_c, twist_per_m, same_hand: bool) -> float:
    """App. 4 by hand: a = atan(C / P), a' from the strained pitch and circumference."""
    r, p, e_i = 9.2e-3, 0.174, 19.5e9
    c = 2 * math.pi * r
    theta = twist_per_m * p  # rotation over one pitch
    a = math.atan(c / p)
    a_s = math.atan((c + (1 if same_hand else -1) * r * theta) / (p * (1 + e_c)))
    return e_i * abs(math.cos(a) / math.cos(a_s) * (1 + e_c) - 1)


def _cable(**kw) -> HelixCable:
    return dataclasses.replace(VAPS, **kw)


def test_free_twist_is_the_seed_model():
    # e_c = T / (A_c E_c), theta / P = G_c T: the CABLE1 assumption, unchanged
    e, tw = core_strain_twist(np.array([8900.0]), VAPS)
    assert e[0] == pytest.approx(8900 / AE, rel=1e-15)
    assert tw[0] == pytest.approx(GC * 8900, rel=1e-15)
    s = conductor_stress(np.array([8900.0, 9800.0]), VAPS, "left")
    assert s == pytest.approx([_knapp(t / AE, GC * t, True) for t in (8900.0, 9800.0)], rel=1e-10)


def test_restrained_twist_no_twist_and_lay_hand_irrelevant():
    cable = _cable(twist_restraint="restrained")
    t = np.array([8900.0, 9800.0])
    left, right = conductor_stress(t, cable, "left"), conductor_stress(t, cable, "right")
    np.testing.assert_array_equal(left, right)
    assert left == pytest.approx([_knapp(x / AE, 0.0, True) for x in t], rel=1e-10)
    # small-strain hand calculation: sigma ~ E_i e_c cos^2 a = 19.5e9 * 2.597e-3 * 0.9006
    cos2a = 1 / (1 + (2 * math.pi * 9.2e-3 / 0.174) ** 2)
    assert left[0] == pytest.approx(19.5e9 * 8900 / AE * cos2a, rel=2e-3)
    assert left[0] / 1e6 == pytest.approx(45.6, abs=0.05)


def test_restrained_torque_balance_stiffens_the_core():
    # M = -K_c G_c T, e_c = T (1/(A_c E_c) - G_c^2 K_c): with K_c = 10 N m^2 the core is
    # 2.04 % stiffer in strain (G_c^2 K_c A_c E_c = 5.954e-10 * 10 * 3.427e6)
    cable = _cable(twist_restraint="restrained", core_torsional_stiffness_Nm2=10.0)
    e, tw = core_strain_twist(np.array([8900.0]), cable)
    assert tw[0] == 0.0
    assert e[0] == pytest.approx(8900 * (1 / AE - GC ** 2 * 10.0), rel=1e-13)
    assert e[0] / (8900 / AE) == pytest.approx(1 - 0.0204, abs=1e-4)
    assert conductor_stress(8900.0, cable, "left") == pytest.approx(_knapp(e[0], 0.0, True), rel=1e-10)
    with pytest.raises(ValueError, match="G_c"):  # restraining must leave a positive stretch
        _cable(core_torsional_stiffness_Nm2=1.01 / (GC ** 2 * AE))


def test_limited_twist_bridle():
    # twist free until G_c T L = Phi: T* = 1.309 rad / (40 m * 24.4e-6) = 1341 N
    cable = _cable(twist_restraint="limited", twist_limit_rad=BRIDLE, twist_length_m=LENGTH)
    t_star = BRIDLE / (LENGTH * GC)
    assert t_star == pytest.approx(1341.2, abs=0.1)
    below = np.array([0.0, 500.0, t_star * (1 - 1e-12)])
    np.testing.assert_allclose(conductor_stress(below, cable, "left"), conductor_stress(below, VAPS, "left"),
                               rtol=1e-10)
    _, tw = core_strain_twist(np.array([8900.0, 9800.0]), cable)
    np.testing.assert_allclose(tw, BRIDLE / LENGTH, rtol=1e-15)
    for lay, same in (("left", True), ("right", False)):
        got = conductor_stress(np.array([8900.0]), cable, lay)[0]
        assert got == pytest.approx(_knapp(8900 / AE, BRIDLE / LENGTH, same), rel=1e-10)
    # with a torsional stiffness the held torque also shortens the core: e_c + G_c M
    stiff = dataclasses.replace(cable, core_torsional_stiffness_Nm2=10.0)
    e, _ = core_strain_twist(np.array([8900.0]), stiff)
    assert e[0] == pytest.approx(8900 / AE + GC * (BRIDLE / LENGTH - GC * 8900) * 10.0, rel=1e-13)
    # the limits: no room to twist = restrained; room beyond any load = free
    t = np.linspace(0, 44e3, 9)
    zero = _cable(twist_restraint="limited", twist_limit_rad=0.0)
    np.testing.assert_allclose(conductor_stress(t, zero, "left"),
                               conductor_stress(t, _cable(twist_restraint="restrained"), "left"), rtol=1e-10)
    wide = _cable(twist_restraint="limited", twist_limit_rad=1e3, twist_length_m=1.0)
    np.testing.assert_allclose(conductor_stress(t, wide, "left"), conductor_stress(t, VAPS, "left"), rtol=1e-10)


def _docs_table() -> dict:
    return json.loads((Path(__file__).parent / "reference" / "issue20_twist_table.json").read_text())


def test_failure_loads_table_matches_docs():
    """The table of docs/CONDUCTOR.md: left and right lay at the lab failure loads (App. 2)."""
    table = _docs_table()
    cables = {"free": VAPS, "restrained": _cable(twist_restraint="restrained"),
              "limited_75deg_over_40m": _cable(twist_restraint="limited", twist_limit_rad=BRIDLE,
                                               twist_length_m=LENGTH)}
    loads = np.array(table["tension_kN"]) * 1e3
    by_hand = {"free": lambda t: (t / AE, GC * t), "restrained": lambda t: (t / AE, 0.0),
               "limited_75deg_over_40m": lambda t: (t / AE, min(GC * t, BRIDLE / LENGTH))}
    for case, cable in cables.items():
        for lay in ("left", "right"):
            got = conductor_stress(loads, cable, lay) / 1e6
            np.testing.assert_allclose(got, table[case][lay + "_MPa"], rtol=0, atol=0.05 + 1e-9)
            oracle = [_knapp(*by_hand[case](t), lay == "left") / 1e6 for t in loads]
            np.testing.assert_allclose(oracle, table[case][lay + "_MPa"], rtol=0, atol=0.05 + 1e-9)
    # the seed's 60 % (section 10) holds for free twist only
    free = table["free"]
    assert np.array(free["right_MPa"]) / np.array(free["left_MPa"]) == pytest.approx(0.594, abs=0.002)


def test_compiled_restrained_path_equals_numpy_and_general():
    cable = _cable(twist_restraint="restrained", core_torsional_stiffness_Nm2=3.0)
    t = np.linspace(0.0, 45e3, 1001)
    fast = conductor_stress(t, cable, "right")
    np.testing.assert_array_equal(fast, axial_stress_oracle(t, cable, "right"))
    general = conductor_stress(t, dataclasses.replace(cable, core_compressibility=1e-30), "right")
    np.testing.assert_allclose(fast, general, rtol=1e-9, atol=1e-3)


def test_inverse_and_bad_input():
    cable = _cable(twist_restraint="limited", twist_limit_rad=BRIDLE, twist_length_m=LENGTH)
    s = conductor_stress(np.array([2000.0, 8900.0]), cable, "left")
    np.testing.assert_allclose(tension_for_stress(s, cable, "left"), [2000.0, 8900.0], rtol=1e-9)
    with pytest.raises(ValueError, match="NaN"):
        conductor_stress(np.array([1.0, np.nan]), cable, "left")
    for bad in ({"twist_restraint": "locked"}, {"twist_limit_rad": -1.0}, {"twist_limit_rad": math.inf},
                {"twist_length_m": 0.0}, {"core_torsional_stiffness_Nm2": -1.0},
                {"conductor_yield_Pa": 0.0}):
        with pytest.raises(ValueError):
            _cable(**bad)
