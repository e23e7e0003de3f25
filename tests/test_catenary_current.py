"""Steady-current solver against the still-water catenary and seeds 001/002."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.catenary import Joint, Line, Segment, solve
from models.catenary.current import Drag, solve_in_current
from models.catenary.closed_forms import current_cord_tension
from models.dynamics import critical_angle, hydrodynamic_constant


def test_no_current_equals_catenary_multisegment():
    line = Line((Segment(40.0, 60.0, 5e6), Segment(60.0, 15.0, 2e6)), (Joint(200.0),),
                seabed=False)
    cur = solve_in_current(line, 70.0, 40.0, 0.0, Drag(0.05))
    ref = solve(line, 70.0, 40.0)
    assert cur.h_top == pytest.approx(float(ref.h), rel=1e-8)
    assert cur.v_top == pytest.approx(float(ref.v_top), rel=1e-8)
    assert cur.v_anchor == pytest.approx(float(ref.v_anchor), rel=1e-8)
    p = ref.profile(11)
    np.testing.assert_allclose(np.interp(p.s, cur.s, cur.z), p.z, atol=1e-3)


def test_straight_line_at_seed002_critical_angle():
    # current towards the anchor (u < 0): weight and normal drag balance on a straight line at
    # the critical angle; choose the span so that the stretch fits anchor tension 1000 N
    w, d, cd, rho, u, ea, length = 30.0, 0.04, 1.2, 1025.0, -1.2, 2e6, 200.0
    alpha = float(critical_angle(abs(u), hydrodynamic_constant(w, cd, d, rho)))
    t_a = 1000.0
    stretched = length + (t_a * length + 0.5 * w * math.sin(alpha) * length**2) / ea
    line = Line.homogeneous(length, w, ea, seabed=False)
    sol = solve_in_current(line, stretched * math.cos(alpha), stretched * math.sin(alpha), u,
                           Drag(d, cd, rho=rho))
    np.testing.assert_allclose(sol.angle, alpha, atol=1e-7)
    assert math.hypot(sol.h_anchor, sol.v_anchor) == pytest.approx(t_a, rel=1e-6)
    # no tangential drag: top tension = bottom tension + weight x (unstretched) rise
    assert sol.t_top == pytest.approx(t_a + w * length * math.sin(alpha), rel=1e-7)


def test_uniform_stream_follows_seed001_eq11():
    w, d, cd, rho, u = 20.0, 0.05, 1.0, 1000.0, 0.8
    line = Line.homogeneous(120.0, w, seabed=False)
    sol = solve_in_current(line, 60.0, 80.0, u, Drag(d, cd, rho=rho), steps=1000)
    lam = 0.5 * rho * cd * d * u * u / w
    expected = current_cord_tension(sol.angle, lam, sol.h_top, float(sol.angle[-1]))
    # eq 10 assumes the cord rises everywhere (normal drag ~ sin^2); near the anchor this one
    # leaves downwards, so compare on the rising part connected to the top
    rising = np.flatnonzero(sol.angle <= 0.0)
    first = rising[-1] + 1 if rising.size else 0
    assert first < sol.s.size // 2
    np.testing.assert_allclose(sol.tension[first:], expected[first:], rtol=1e-7)
    # horizontal equilibrium: the anchor takes the fairlead's pull plus the whole drag,
    # D_x = rho C d |u sin(a)| u sin^2(a) / 2 per metre
    kn = 0.5 * rho * cd * d
    dx = kn * abs(u * np.sin(sol.angle)) * u * np.sin(sol.angle) ** 2
    total = float(np.sum(0.5 * (dx[1:] + dx[:-1]) * np.diff(sol.s)))
    assert sol.h_anchor - sol.h_top == pytest.approx(total, rel=1e-5)
    assert sol.h_anchor > float(solve(line, 60.0, 80.0).h_anchor)  # pulled downstream


def test_sheared_profile_and_errors():
    line = Line.homogeneous(100.0, 25.0, 1e7, seabed=False)
    sol = solve_in_current(line, 50.0, 60.0, lambda z: 0.02 * z, Drag(0.03, 1.2, 0.3))
    assert sol.x[-1] == pytest.approx(50.0, abs=1e-6) and sol.z[-1] == pytest.approx(60.0, abs=1e-6)
    # with tangential drag the tension is no longer bottom + w * height
    assert sol.t_top - math.hypot(sol.h_anchor, sol.v_anchor) != pytest.approx(25.0 * 60.0,
                                                                              rel=1e-4)
    with pytest.raises(ValueError, match="seabed"):
        solve_in_current(Line.homogeneous(100.0, 25.0), 50.0, 20.0, 0.5, Drag(0.03))
    with pytest.raises(ValueError, match="diameters"):
        solve_in_current(line, 50.0, 60.0, 0.5, Drag((0.03, 0.04)))
    with pytest.raises(ValueError, match="current"):
        solve_in_current(line, 50.0, 60.0, math.nan, Drag(0.03))
