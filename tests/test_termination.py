"""Conductor stress in the termination moulding (issue 20, seed 004 App. 3A bend geometry)."""

import dataclasses
import math

import numpy as np
import pytest

from models import termination
from models.helix import HelixCable, axial_kernel_args, conductor_stress, stress_terms
from models.termination import TerminationBend, bend_arc_lengths, bend_strain, termination_stress

VAPS = HelixCable.vaps_biw()


def test_app3a_bend_test_numbers():
    # App. 3A: 76.2 mm mandrel (r 38.1) + cable radius 15.5 mm, quarter turn, conductor 9.2 mm
    # further out; gauge (190.5 + 609.6) mm / cos 18.25 deg = 842.5 mm; unit strain .0172;
    # E = 241.3 MPa / .0172 = 14.03 GPa
    gauge = (190.5 + 609.6) / math.cos(math.radians(18.25)) / 1e3
    assert gauge * 1e3 == pytest.approx(842.5, abs=0.05)
    bend = TerminationBend(bend_radius_m=(38.1 + 15.5) / 1e3, bend_angle_rad=math.pi / 2, gauge_length_m=gauge)
    neutral, conductor = bend_arc_lengths(bend, 9.2e-3)
    assert neutral * 1e3 == pytest.approx(84.19, abs=0.005)
    assert conductor * 1e3 == pytest.approx(98.65, abs=0.005)
    assert (conductor - neutral) * 1e3 == pytest.approx(14.46, abs=0.01)
    eps = bend_strain(bend, 9.2e-3)
    assert eps == pytest.approx(0.0172, abs=0.00005)
    assert 241.3e6 / eps / 1e9 == pytest.approx(14.03, abs=0.04)


def test_locked_conductor_strain_is_helix_radius_over_bend_radius():
    # the moulding locks the conductor: gauge = neutral arc, strain R_i / r_1 for any angle
    for angle in (1e-6, 0.3, math.pi / 2):
        assert bend_strain(TerminationBend(0.6, angle), 9.2e-3) == pytest.approx(9.2e-3 / 0.6, rel=1e-15)
    assert bend_strain(TerminationBend(0.6, 0.0), 9.2e-3) == 0.0  # straight: no bend


def test_termination_stress_ductile_rule():
    bend = TerminationBend(bend_radius_m=0.6, bend_angle_rad=0.2)
    t = np.array([0.0, 4450.0, 8900.0])
    sa, sb, tau = stress_terms(t, VAPS, "left")
    sigma_bend = 19.5e9 * 9.2e-3 / 0.6  # 299.0 MPa
    want = np.sqrt((sa + sb + sigma_bend) ** 2 + 3 * tau ** 2)
    got = termination_stress(t, VAPS, "left", bend)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-3)  # trig-free (fast) against App. 4 (Pa)
    assert got[0] / 1e6 == pytest.approx(299.0, abs=1e-9)  # the bend alone, at zero tension
    # the shear and helix-bending terms are ~1e-3 of the axial term (App. 4): the range of a
    # 0 -> 8.9 kN cycle is the free span's axial stress range within 0.5 %
    assert got[2] - got[0] == pytest.approx(conductor_stress(8900.0, VAPS, "left"), rel=5e-3)
    # no bend: the free span's combined stress
    straight = TerminationBend(bend_radius_m=1.0, bend_angle_rad=0.0, gauge_length_m=1.0)
    np.testing.assert_allclose(termination_stress(t, VAPS, "right", straight),
                               conductor_stress(t, VAPS, "right", combined=True), rtol=1e-13, atol=1e-3)


@pytest.mark.parametrize("twist", [{}, {"twist_restraint": "restrained", "core_torsional_stiffness_Nm2": 3.0},
                                   {"twist_restraint": "limited", "twist_limit_rad": 1.309, "twist_length_m": 40.0}])
@pytest.mark.parametrize("lay", ["left", "right"])
def test_fast_path_equals_app4_and_compiled_equals_numpy(twist, lay):
    cable = dataclasses.replace(VAPS, **twist)
    bend = TerminationBend(0.6, 0.5)
    t = np.random.default_rng(3).uniform(0.0, 45e3, 5000)
    sa, sb, tau = stress_terms(t, cable, lay)
    want = np.sqrt((sa + sb + 19.5e9 * 9.2e-3 / 0.6) ** 2 + 3 * tau ** 2)
    got = termination_stress(t, cable, lay, bend)
    np.testing.assert_allclose(got, want, rtol=1e-13)
    args = axial_kernel_args(cable, lay)
    if args is not None:  # the compiled loop: against its per-sample formula on arrays
        coefs = termination._coefficients(cable, args, 19.5e9 * 9.2e-3 / 0.6)
        np.testing.assert_array_equal(got, termination._stress(t, *coefs))
    with pytest.raises(ValueError, match="NaN"):
        termination_stress(np.array([1.0, np.nan]), cable, lay, bend)


def test_twist_restraint_applies_at_the_termination():
    bend = TerminationBend(0.6, 0.2)
    held = dataclasses.replace(VAPS, twist_restraint="restrained")
    left = termination_stress(np.array([8900.0]), held, "left", bend)
    right = termination_stress(np.array([8900.0]), held, "right", bend)
    np.testing.assert_allclose(left, right, rtol=1e-12)


def test_bad_geometry_and_input():
    for kw in ({"bend_radius_m": 0.0, "bend_angle_rad": 0.1}, {"bend_radius_m": 0.5, "bend_angle_rad": -0.1},
               {"bend_radius_m": 0.5, "bend_angle_rad": 4.0}, {"bend_radius_m": math.nan, "bend_angle_rad": 0.1},
               {"bend_radius_m": 0.5, "bend_angle_rad": 0.1, "gauge_length_m": 0.0}):
        with pytest.raises(ValueError):
            TerminationBend(**kw)
    with pytest.raises(ValueError, match="NaN"):
        termination_stress(np.array([1.0, np.inf]), VAPS, "left", TerminationBend(0.6, 0.2))
