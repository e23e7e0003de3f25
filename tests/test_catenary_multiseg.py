"""Multi-segment lines: seed 004's mooring, random robustness sweep, TensionTable, inverse."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.catenary import (
    VAPS_DEPTH,
    Joint,
    Line,
    Segment,
    TensionTable,
    solve,
    solve_line,
    span_from_top_tension,
    vaps_mooring,
)


def test_vaps_mooring_definition():
    line = vaps_mooring()
    bridle, floated, bare = line.segments
    assert line.length == pytest.approx(40.0)
    assert (bridle.length, floated.length, bare.length) == (2.5, 17.5, 20.0)
    # documented assumptions: 3.4 N/m bare, -34.3 N/m jacketed, core EA 3.43 MN
    assert bare.weight == pytest.approx((1.10 - 1000.0 * math.pi / 4 * 0.031**2) * 9.81)
    assert bare.weight == pytest.approx(3.39, abs=0.01)
    assert floated.weight == pytest.approx(-34.33, abs=0.01)
    assert bare.ea == pytest.approx(4.21e-5 * 81.4e9)
    # fitting + floats + bridle are neutral in water; the dry mass rides on the joint
    assert bridle.weight * bridle.length + line.joints[0].weight == pytest.approx(0.0, abs=1e-9)
    assert line.joints[0].mass == 14.4
    assert bridle.weight * bridle.length / 9.81 == pytest.approx(11.1 * (1 - 1000 / 7850))
    with pytest.raises(ValueError, match="jacket_diameter"):
        vaps_mooring(jacket_diameter=0.02)
    with pytest.raises(ValueError, match="water_density"):
        vaps_mooring(water_density=math.nan)


def test_vaps_calm_and_offset_shapes():
    line = vaps_mooring()
    x = np.array([0.0, 5.0, 15.0, 25.0, 30.0, 32.0])
    sol = solve(line, x, np.full_like(x, VAPS_DEPTH))
    assert np.all(sol.regime == 0)  # the float lifts everything off the bottom
    # V_top - V_anchor = total submerged weight (-533 N: the line is buoyant overall)
    np.testing.assert_allclose(sol.v_top - sol.v_anchor, line.weight, rtol=1e-12)
    # the floated section stands up from the anchor: anchor pulled up by ~ its net buoyancy
    assert np.all(sol.v_anchor > 500.0)
    # top tension grows monotonically with offset; at calm it is the bare cable's sag
    assert np.all(np.diff(sol.t_top) > 0.0)
    assert 0.0 < float(sol.t_top[0]) < 20.0 * 3.39 + 1e-9
    # joint tensions just above the fitting: V = V_anchor + bridle + fitting/floats = V_anchor
    np.testing.assert_allclose(sol.joint_v[:, 0], sol.v_anchor, rtol=1e-12)
    np.testing.assert_allclose(sol.joint_v[:, 1], sol.v_top - 20.0 * line.segments[2].weight,
                               rtol=1e-12)
    np.testing.assert_allclose(sol.joint_h[:, 1], sol.h, rtol=1e-12)
    p = sol[3].profile(81)
    assert p.x[-1] == pytest.approx(25.0, abs=1e-8)
    assert p.z.max() <= VAPS_DEPTH + 1e-9 and p.z.min() >= 0.0


def _random_line(rng, seabed: bool, heavy: bool) -> Line:
    n = int(rng.integers(1, 4))
    segs = []
    for _ in range(n):
        length = rng.uniform(5.0, 100.0)
        sign = 1.0 if heavy else float(rng.choice([1.0, 1.0, -1.0]))
        w = sign * 10 ** rng.uniform(-0.5, 2.5)
        ea = float(rng.choice([math.inf, 10 ** rng.uniform(3.0, 8.0) * abs(w) * length]))
        segs.append(Segment(length, w, ea))
    signs = [1.0] if heavy else [0.0, 1.0, -1.0]
    joints = [Joint(float(rng.choice(signs) * 10 ** rng.uniform(0.0, 3.0))) for _ in segs[1:]]
    mu = float(rng.uniform(0.0, 1.0)) if seabed and rng.random() < 0.5 else 0.0
    return Line(tuple(segs), tuple(joints), seabed, mu)


def test_random_multisegment_sweep_never_fails():
    """Free lines of any weights and all-heavy lines on a seabed: every geometry solves and
    satisfies vertical equilibrium and the fairlead position (through the profile)."""
    rng = np.random.default_rng(2024)
    regimes = set()
    for i in range(400):
        seabed = i % 2 == 0
        line = _random_line(rng, seabed, heavy=seabed)
        frac = rng.uniform(0.02, 1.0 if line.inextensible else 1.03)
        ang = rng.uniform(0.0 if seabed else -1.5, 1.5)
        x = frac * line.length * math.cos(ang)
        z = frac * line.length * math.sin(ang)
        if line.inextensible and math.hypot(x, z) >= line.length:
            continue
        sol = solve(line, x, z)
        regimes.add(int(sol.regime))
        t_scale = float(sol.t_top) + abs(line.weight)
        if float(sol.grounded_length) == 0.0:
            assert float(sol.v_top - sol.v_anchor) == pytest.approx(line.weight,
                                                                    abs=1e-9 * t_scale)
        if float(sol.h) > 0.0 and i % 4 < 2:
            p = sol.profile(15)
            assert p.x[-1] == pytest.approx(x, abs=1e-6 * line.length)
            assert p.z[-1] == pytest.approx(z, abs=1e-6 * line.length)
    assert regimes >= {0, 1, 2, 3}


def test_mixed_lines_on_seabed_solve_or_say_why():
    rng = np.random.default_rng(77)
    solved = 0
    for _ in range(150):
        line = _random_line(rng, True, heavy=False)
        frac = rng.uniform(0.02, 0.99)
        ang = rng.uniform(0.0, 1.5)
        x, z = frac * line.length * math.cos(ang), frac * line.length * math.sin(ang)
        try:
            sol = solve(line, x, z)
        except ValueError as err:
            assert "seabed" in str(err)
            continue
        solved += 1
        assert np.isfinite(float(sol.t_top)) and float(sol.grounded_length) >= 0.0
    assert solved > 75


def test_clump_pinned_touchdown_matches_fine_split():
    # chain + clump + light rope: the touchdown sits at the clump; compare with the clump
    # spread over a short heavy segment (the same weight) -> close answers
    chain = Segment(86.7, 10.7)
    rope = Segment(41.2, 1.03, 2e8)
    pinned = solve(Line((chain, rope), (Joint(467.0),), True, 0.9), 96.3, 38.8)
    spread = solve(Line((Segment(86.7 - 1e-4, 10.7), Segment(1e-4, 4.67e6), rope),
                        (Joint(), Joint()), True, 0.9), 96.3, 38.8)
    assert float(pinned.h) == pytest.approx(float(spread.h), rel=1e-4)
    assert float(pinned.v_top) == pytest.approx(float(spread.v_top), rel=1e-4)
    assert float(pinned.h_anchor) == pytest.approx(float(spread.h_anchor), rel=1e-4, abs=1e-6)


def test_tension_table_accuracy_and_speed_contract():
    line = vaps_mooring()
    table = TensionTable(line, (0.0, 31.5), (21.0, 25.0), rtol=1e-4)
    assert table.max_relative_error <= 1e-4
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 31.5, 400)
    z = rng.uniform(21.0, 25.0, 400)
    exact = solve(line, x, z)
    h, v, t = table.top_tension(x, z)
    # between check points the error is of the same order: allow 3x the measured worst
    assert np.max(np.abs(h - exact.h)) <= 3 * table.max_error + 1e-9
    assert np.max(np.abs(v - exact.v_top)) <= 3 * table.max_error + 1e-9
    np.testing.assert_allclose(t, exact.t_top, rtol=1e-3)
    f = table.forces(x, z, stiffness=True)
    np.testing.assert_allclose(f.stiffness, exact.stiffness, rtol=0.05,
                               atol=0.02 * np.abs(exact.stiffness).max())
    with pytest.raises(ValueError, match="span outside"):
        table.top_tension(32.0, 23.0)
    with pytest.raises(ValueError, match="height outside"):
        table.top_tension(10.0, math.nan)


def test_span_from_top_tension_round_trip():
    for line, x, z in ((Line.homogeneous(100.0, 20.0, 1e6, True, 0.3),
                        np.linspace(52.0, 80.0, 9), 50.0),
                       (Line.homogeneous(100.0, 20.0), np.linspace(51.0, 86.0, 9), 50.0),
                       (vaps_mooring(), np.linspace(0.5, 32.5, 9), VAPS_DEPTH),
                       (Line.homogeneous(100.0, 20.0, seabed=False), np.linspace(1, 86, 9),
                        -20.0)):
        zz = np.full_like(x, z)
        sol = solve(line, x, zz)
        back = span_from_top_tension(line, sol.t_top, zz)
        np.testing.assert_allclose(back.span, x, atol=1e-5)
        np.testing.assert_allclose(back.top_angle, sol.top_angle, atol=1e-7)
    one = span_from_top_tension(Line.homogeneous(100.0, 20.0), 3000.0, 50.0)
    assert float(solve_line(float(one.span), 50.0, 100.0, 20.0).t_top) == pytest.approx(3000.0)
    with pytest.raises(ValueError, match="slack minimum"):
        span_from_top_tension(Line.homogeneous(100.0, 20.0), 500.0, 50.0)
    with pytest.raises(ValueError, match="reach"):
        span_from_top_tension(Line.homogeneous(100.0, 20.0), 1e12, 50.0)
