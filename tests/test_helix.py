"""Helix conductor stress against seed 004's CABLE1/2/3 tables and section 8/10 figures."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fatigue_oracles import axial_stress_oracle
from models.helix import (HelixCable, conductor_stress, sweep_helix_diameter, sweep_pitch,
                          tension_for_stress)


def _shared() -> Path:
    # beside the checkout in CI (<repo>/../shared); a level higher for nested worktrees
    for parent in Path(__file__).resolve().parents[1:4]:
        if (parent / "shared" / "reference").is_dir():
            return parent / "shared"
    pytest.skip("shared/ reference data not found beside the repository")


def _printed(actual, printed, decimals: int) -> None:
    """``actual`` agrees with a table printed to ``decimals`` places (any rounding of a tie)."""
    np.testing.assert_allclose(actual, printed, rtol=0, atol=0.5 * 10.0 ** -decimals + 1e-9)


@pytest.fixture(scope="module")
def ref() -> dict:
    return json.loads((_shared() / "reference" / "seed004_vaps_cable.json").read_text())


def _cable1(ref) -> HelixCable:
    d = ref["cable1_program_inputs"]  # CABLE1 DATA line (E_i = 19.3 GPa)
    return dataclasses.replace(HelixCable.vaps_biw(), core_area_m2=d["Ac_m2"], core_modulus_Pa=d["Ec_Pa"],
                               core_twist_modulus=d["Gc"], pitch_m=d["P_m"], helix_radius_m=d["Ri_m"],
                               conductor_modulus_Pa=d["Ei_Pa"])


def _cable2(ref) -> HelixCable:
    d = ref["cable2_program_inputs"]
    return dataclasses.replace(HelixCable.vaps_biw(), core_area_m2=d["Ac_m2"], core_modulus_Pa=d["Ec_Pa"],
                               core_twist_modulus=d["Gc"], pitch_m=d["Pi_m"], helix_radius_m=d["Di_m"] / 2,
                               conductor_modulus_Pa=d["Ei_Pa"], conductor_area_m2=d["Ai_m2"])


def test_cable1_table(ref):
    cable = _cable1(ref)
    table = ref["cable1_stress_vs_tension"]
    tension = np.arange(21) * ref["cable1_program_inputs"]["Tmax_N"] / 20
    _printed(tension / 1e3, table["tension_kN"], 1)
    for lay, key in (("left", "left_lay_MPa"), ("right", "right_lay_MPa")):
        _printed(conductor_stress(tension, cable, lay) / 1e6, table[key], 1)


def test_cable2_table(ref):
    d = ref["cable2_program_inputs"]
    table = ref["cable2_stress_vs_helix_diameter"]
    diameters = d["Di_m"] * 1.05 ** np.arange(15)
    sweep = sweep_helix_diameter(_cable2(ref), d["Fc_N"], diameters)
    _printed(sweep.helix_diameter_m * 1e3, table["helix_dia_mm"], 2)
    _printed(sweep.lay_angle_deg, table["lay_angle_deg"], 2)
    _printed(sweep.stress_left_Pa / 1e6, table["left_stress_MPa"], 2)
    _printed(sweep.stress_right_Pa / 1e6, table["right_stress_MPa"], 2)
    _printed(sweep.cable_load_left_N / 1e3, table["left_cable_load_kN"], 2)
    _printed(sweep.cable_load_right_N / 1e3, table["right_cable_load_kN"], 2)


def test_cable3_table(ref):
    d = ref["cable2_program_inputs"]
    table = ref["cable3_stress_vs_pitch"]
    pitches = d["Pi_m"] * 0.95 ** np.arange(15)
    sweep = sweep_pitch(_cable2(ref), d["Fc_N"], pitches)
    _printed(sweep.pitch_m * 1e3, table["pitch_mm"], 2)
    _printed(sweep.lay_angle_deg, table["lay_angle_deg"], 2)
    _printed(sweep.stress_left_Pa / 1e6, table["left_stress_MPa"], 2)
    _printed(sweep.stress_right_Pa / 1e6, table["right_stress_MPa"], 2)
    # CABLE3 prints no cable-load column; it is the same definition as CABLE2's
    np.testing.assert_allclose(sweep.cable_load_left_N, d["Fc_N"] + sweep.stress_left_Pa * d["Ai_m2"])


def test_right_lay_about_60_percent_of_left():
    cable = HelixCable.vaps_biw()
    t = np.linspace(1e3, 44.5e3, 20)
    ratio = conductor_stress(t, cable, "right") / conductor_stress(t, cable, "left")
    assert np.all((ratio > 0.58) & (ratio < 0.61))


def test_section10_redesign_33mm_right_lay():
    # Section 10: 33 mm helix diameter, 174 mm pitch, right lay -> "32 MPa at 44 kN".
    # The same App. 4 model (which reproduces CABLE2 exactly) gives 36 MPa here; the
    # report's figure is a rounded reading, so only "about" is asserted.
    cable = dataclasses.replace(HelixCable.vaps_biw(), helix_radius_m=0.0165)
    s = conductor_stress(44e3, cable, "right") / 1e6
    assert 30.0 < s < 37.0
    assert s < 0.25 * conductor_stress(44e3, HelixCable.vaps_biw(), "left") / 1e6


def test_predicted_failure_table(ref):
    from models.fatigue import SNCurve

    table = ref["predicted_failure_table"]
    curve = SNCurve.vaps_copper()
    stress = curve.stress_range_at(np.asarray(table["cycles"]))
    _printed(stress / 1e6, table["endurance_stress_MPa"], 1)
    cable = HelixCable.vaps_biw()
    for lay in ("left", "right"):
        load = tension_for_stress(stress, cable, lay)
        np.testing.assert_allclose(conductor_stress(load, cable, lay), stress, rtol=1e-12)
        _printed(load / 1e3, table[f"equivalent_cable_load_{lay}_kN"], 1)


def test_combined_stress_is_axial_plus_small_terms():
    cable = HelixCable.vaps_biw()
    t = np.array([0.0, 5e3, 20e3, 44e3])
    axial = conductor_stress(t, cable, "left")
    combined = conductor_stress(t, cable, "left", combined=True)
    assert combined[0] == 0.0
    rel = (combined[1:] - axial[1:]) / axial[1:]
    assert np.all(np.abs(rel) < 5e-3) and np.all(np.abs(rel) > 0)
    # a thick wire makes the bending and shear terms matter
    thick = dataclasses.replace(cable, conductor_wire_diameter_m=2e-3)
    assert abs(conductor_stress(20e3, thick, "left", combined=True) / axial[2] - 1) > 5 * abs(rel[1])


def test_fast_path_equals_knapp_formula():
    cable = HelixCable.vaps_biw()
    t = np.linspace(0, 45e3, 101)
    c = 2 * np.pi * cable.helix_radius_m
    a = np.arctan(c / cable.pitch_m)
    e = t / (cable.core_area_m2 * cable.core_modulus_Pa)
    theta = cable.core_twist_modulus * t * cable.pitch_m
    for lay, sgn in (("left", 1), ("right", -1)):
        a_s = np.arctan((c + sgn * cable.helix_radius_m * theta) / (cable.pitch_m * (1 + e)))
        expected = cable.conductor_modulus_Pa * np.abs(np.cos(a) / np.cos(a_s) * (1 + e) - 1)
        np.testing.assert_allclose(conductor_stress(t, cable, lay), expected, rtol=1e-12, atol=1e-3)


def test_load_share_and_compressibility():
    cable = HelixCable.vaps_biw()
    half = dataclasses.replace(cable, core_load_share=0.5)
    np.testing.assert_allclose(conductor_stress(20e3, half), conductor_stress(10e3, cable), rtol=1e-12)
    squeezed = dataclasses.replace(cable, core_compressibility=1e-8)  # 0.2 mm at 20 kN
    assert conductor_stress(20e3, squeezed) < conductor_stress(20e3, cable)


def test_bad_input():
    cable = HelixCable.vaps_biw()
    with pytest.raises(ValueError, match="tension_N"):
        conductor_stress(np.array([1.0, np.nan]), cable)
    with pytest.raises(ValueError, match="lay"):
        conductor_stress(1.0, cable, "up")
    with pytest.raises(ValueError, match="pitch_m"):
        dataclasses.replace(cable, pitch_m=-1.0)
    with pytest.raises(ValueError, match="stress_Pa"):
        tension_for_stress(-1.0, cable)


def test_compiled_and_uncompiled_loops_equal_the_numpy_oracle(monkeypatch):
    cable = HelixCable.vaps_biw()
    t = np.random.default_rng(0).uniform(0, 45e3, 5000).reshape(50, 100)
    for lay in ("left", "right"):
        a = conductor_stress(t, cable, lay)
        assert a.shape == t.shape
        np.testing.assert_array_equal(a, axial_stress_oracle(t, cable, lay))
        with monkeypatch.context() as patch:  # without numba: the loop as plain Python
            patch.setattr("models.fatigue._loops.axial_compiled", None)
            np.testing.assert_array_equal(conductor_stress(t[:5], cable, lay), a[:5])
    assert conductor_stress(10e3, cable).shape == ()
    with pytest.raises(ValueError, match="index 3"):
        conductor_stress(np.array([1.0, 2.0, 3.0, np.inf]), cable)
