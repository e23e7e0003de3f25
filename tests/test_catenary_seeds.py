"""The seeds' catenary formulas against the seed tables and against the general solver."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from models import dynamics as dyn
from models.catenary import closed_forms as cs
from models.catenary import solve_line

SHARED = next((p / "shared" for p in Path(__file__).resolve().parents[1:]
               if (p / "shared" / "reference").is_dir()), Path("shared-not-found"))
G = 9.80665  # seed 001 works in kgf


def _reference(name: str) -> dict:
    path = SHARED / "reference" / name
    if not path.is_file():
        pytest.skip(f"seed reference {path} not found (needs ../shared beside the repo)")
    return json.loads(path.read_text())


# --- seed 001 -------------------------------------------------------------------------------

def test_seed001_catenary_table():
    ref = _reference("seed001_anchor_chain.json")["expected"]["catenary_y_for_x"]
    y = cs.touchdown_catenary_y(np.array(ref["x_m"], dtype=float), ref["a_m"])
    np.testing.assert_array_equal(np.round(y, 1), ref["y_m"])


def test_seed001_anchor_chain_statics():
    ref = _reference("seed001_anchor_chain.json")
    inp, exp = ref["inputs"], ref["expected"]
    depth, w_kgf = inp["depth_m"], inp["chain_weight_kgf_per_m"]
    h_kgf = inp["horizontal_force_per_chain_t"] * 1000.0
    suspended = cs.chain_suspended_length(depth, h_kgf, w_kgf)
    top_t = cs.chain_top_tension(depth, h_kgf, w_kgf) / 1000.0
    assert suspended == pytest.approx(160.6, abs=0.05)  # printed "160" (truncated)
    assert math.floor(suspended) // 10 * 10 == exp["suspended_length_m"]
    assert round(top_t, 1) == exp["static_top_tension_t"]
    # the same chain through the general solver (SI): find the span that gives H, then the
    # grounded length and top tension must agree with the seed's closed forms
    w = w_kgf * G
    length = inp["chain_length_m"]
    a = h_kgf / w_kgf
    span = length - suspended + a * math.asinh(suspended / a)
    sol = solve_line(span, float(depth), float(length), w)
    assert float(sol.h) == pytest.approx(h_kgf * G, rel=1e-9)
    assert length - float(sol.grounded_length) == pytest.approx(suspended, rel=1e-9)
    assert float(sol.t_top) / G / 1000.0 == pytest.approx(top_t, rel=1e-9)
    # eq 2 and eq 3 along the same chain
    assert cs.touchdown_tension(h_kgf, w_kgf, depth) == pytest.approx(top_t * 1000.0)
    assert cs.touchdown_suspended_length(depth, a) == pytest.approx(suspended)


def test_seed001_current_cord_matches_its_ode():
    # eq 10 with dT = w dy: dT/T = dbeta / (lam sin(beta) + cot(beta)); integrate numerically
    lam, p0, beta_top = 0.8, 1000.0, 1.2
    betas = np.linspace(beta_top, 0.3, 20001)
    f = 1.0 / (lam * np.sin(betas) + 1.0 / np.tan(betas))
    log_t = np.concatenate(([0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(betas))))
    t_ode = p0 / math.cos(beta_top) * np.exp(log_t)
    t_eq11 = cs.current_cord_tension(betas, lam, p0, beta_top)
    np.testing.assert_allclose(t_eq11, t_ode, rtol=1e-8)


# --- seed 002 -------------------------------------------------------------------------------

def test_critical_angle_is_the_singular_angle_of_seed001_eq11():
    # (V/H)^2 = (rho C_D d V^2 / 2) / w = lam: seed 002's critical angle is where seed 001's
    # cord-in-current tension blows up (for beta measured on the upstream side, pi - alpha)
    w, cd, rho, d, v = 40.0, 1.2, 1025.0, 0.03, 1.5
    hc = dyn.hydrodynamic_constant(w, cd, d, rho)
    lam = 0.5 * rho * cd * d * v * v / w
    assert (v / hc) ** 2 == pytest.approx(lam)
    alpha = float(dyn.critical_angle(v, hc))
    s = math.sqrt(4 * lam * lam + 1)
    assert math.cos(math.pi - alpha) == pytest.approx((1 - s) / (2 * lam), rel=1e-12)
    # weight and normal drag balance there: w cos(alpha) = lam w sin^2(alpha)
    assert math.cos(alpha) == pytest.approx(lam * math.sin(alpha) ** 2, rel=1e-12)


# --- seed 003 -------------------------------------------------------------------------------

def test_seed003_closed_form_end_forces():
    ref = _reference("seed003_low_tension_cable.json")
    setup = ref["setup"]
    for i, q in enumerate(ref["q_m"]):
        for j, h in enumerate(ref["h_m"]):
            hh, va, vb = cs.filipich_end_forces(setup["cable_length_m"], setup["A_m"] + q,
                                                setup["B_m"] + h,
                                                setup["weight_per_length_N_per_m"])
            assert hh == pytest.approx(ref["H_exact_N"][i][j], abs=1e-6)
    hh, va, vb = cs.filipich_end_forces(47.0, 40.0, 20.0, 50.0)
    assert vb == pytest.approx(2093.18438130291, abs=1e-6)
    assert va == pytest.approx(-256.81561869709, abs=1e-6)
    assert vb - va == pytest.approx(50.0 * 47.0)
    with pytest.raises(ValueError):
        cs.filipich_end_forces(40.0, 40.0, 20.0, 50.0)


# --- seed 000 -------------------------------------------------------------------------------

def test_seed000_constant_stress_catenary_table2():
    ref = _reference("seed000_constant_stress_catenary.json")
    y = cs.constant_stress_catenary_y(np.array(ref["x_ft"], dtype=float), ref["c_ft"])
    np.testing.assert_allclose(y, ref["y_ft"], atol=0.021)  # table printed to 0.01 ft


def test_seed000_other_checks():
    ref = _reference("seed000_constant_stress_catenary.json")["other_checks"]
    # 100,000 psi steel wire rope, 262 lb/ft^3: self-supporting length in ft = 144 sigma/gamma
    assert round(cs.self_support_length(144 * 100_000.0, 262.0)) == ref["self_support_length_ft"]
    # Fig. 17: the constant-stress curve tangent at (0, 0) through (1000, 10000) ft
    c = cs.constant_stress_parameter(1000.0, 10_000.0)
    assert float(cs.constant_stress_catenary_y(1000.0, c)) == pytest.approx(10_000.0)
    length = float(cs.constant_stress_catenary_length(10_000.0, c))
    assert round(length, 1) == ref["length_through_1000_10000_ft"]


def test_seed000_e_taper_relations():
    gamma, sigma, a0 = 262.0, 144 * 100_000.0, 0.1
    s = np.linspace(0.0, 20_000.0, 5)
    area = cs.e_taper_area(s, a0, gamma, sigma)
    # eq 10/11: the weight hanging below s equals the tension rise sigma (A - A0)
    np.testing.assert_allclose(cs.e_taper_weight(s, a0 * sigma, gamma, sigma),
                               sigma * (area - a0), rtol=1e-12)
    assert float(cs.vertical_cable_tension(100.0, 2.0, 50.0)) == 250.0


def test_general_gravity_integrator_reproduces_both_catenaries():
    # constant-stress area (eq 19) -> eq 17; constant weight -> seed 001 eq 1
    c, t_h, gamma = 3284.0, 5.0e4, 262.0
    sigma = c * gamma
    s = np.linspace(0.0, 4000.0, 4001)
    w = gamma * cs.constant_stress_area(s, t_h, sigma, c)
    x, y, t = cs.gravity_cable_shape(s, w, t_h)
    np.testing.assert_allclose(y, cs.constant_stress_catenary_y(x, c), rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(t / (w / gamma), sigma, rtol=1e-7)  # constant stress
    x, y, t = cs.gravity_cable_shape(s, 10.0, 2000.0)
    np.testing.assert_allclose(y, cs.touchdown_catenary_y(x, 200.0), rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(t, cs.touchdown_tension(2000.0, 10.0, y), rtol=1e-9)
