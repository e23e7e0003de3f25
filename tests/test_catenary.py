"""Single- and multi-segment catenary: seed 003 table, MoorPy sweep, relational checks."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from models.catenary import REGIMES, Joint, Line, Segment, solve, solve_line

# shared/ sits beside the checkout (CI) or higher up (worktrees under /work/<dir>/)
SHARED = next((p / "shared" for p in Path(__file__).resolve().parents[1:]
               if (p / "shared" / "reference").is_dir()), Path("shared-not-found"))


def _reference(name: str) -> dict:
    path = SHARED / "reference" / name
    if not path.is_file():
        pytest.skip(f"seed reference {path} not found (needs ../shared beside the repo)")
    return json.loads(path.read_text())


# --- seed 003: inextensible cable, both ends free of the seabed ---------------------------

def test_seed003_exact_horizontal_tension_grid():
    ref = _reference("seed003_low_tension_cable.json")
    setup = ref["setup"]
    q = np.array(ref["q_m"])
    h = np.array(ref["h_m"])
    expected = np.array(ref["H_exact_N"])  # rows: q, columns: h
    Q, Hh = np.meshgrid(q, h, indexing="ij")
    sol = solve_line(setup["A_m"] + Q, setup["B_m"] + Hh, setup["cable_length_m"],
                     setup["weight_per_length_N_per_m"], seabed=False)
    np.testing.assert_allclose(sol.h, expected, rtol=0, atol=1e-6)
    assert np.all(sol.regime == 0)


def test_seed003_end_forces_at_origin():
    sol = solve_line(40.0, 20.0, 47.0, 50.0, seabed=False)
    assert float(sol.v_top) == pytest.approx(2093.18438130291, abs=1e-6)
    assert float(sol.t_top) == pytest.approx(2657.73329606183, abs=1e-6)
    assert float(sol.v_anchor) == pytest.approx(-256.81561869709, abs=1e-6)
    # the same geometry on a seabed: V_A < 0 is impossible, part of the cable lies down
    on_bed = solve_line(40.0, 20.0, 47.0, 50.0)
    assert float(on_bed.grounded_length) > 0.0
    assert float(on_bed.v_anchor) == 0.0


# --- MoorPy on a random sweep of every regime ----------------------------------------------

def _sweep(n: int, seed: int = 4):
    rng = np.random.default_rng(seed)
    cases = []
    while len(cases) < n:
        length = rng.uniform(10.0, 500.0)
        weight = float(rng.choice([1.0, 1.0, 1.0, -1.0]) * 10 ** rng.uniform(0.0, 3.0))
        ea = float(10 ** rng.uniform(3.0, 9.0) * abs(weight) * length)
        seabed = weight > 0 and rng.random() < 0.7
        mu = float(rng.choice([0.0, rng.uniform(0.0, 1.5)])) if seabed else 0.0
        frac = rng.uniform(0.05, 1.02)
        angle = rng.uniform(0.0 if seabed else -math.pi / 2, math.pi / 2)
        kind = rng.random()
        if kind < 0.04:
            angle = math.pi / 2  # vertical
        elif kind < 0.08 and seabed:
            angle = 0.0  # fairlead on the seabed
        x = frac * length * math.cos(angle)
        z = frac * length * math.sin(angle)
        if x < 1e-9 * length:
            x = 0.0
        elif x < 2e-4 * abs(z):
            continue  # MoorPy switches to a vertical-line approximation there
        cases.append((x, z, length, weight, ea, seabed, mu))
    return cases


def test_moorpy_random_sweep_every_regime():
    catenary = pytest.importorskip("moorpy.Catenary").catenary
    compared = 0
    regimes = set()
    for x, z, length, weight, ea, seabed, mu in _sweep(320):
        sol = solve_line(x, z, length, weight, ea, seabed, mu)
        cb = mu if seabed else -1e7  # MoorPy: CB < 0 = seabed that far below end A
        fa_h, fa_v, fb_h, fb_v, info = catenary(x, z, length, ea, weight, CB=cb, Tol=1e-11,
                                                MaxIter=1000)
        if info["ProfileType"] == -1:
            continue  # MoorPy's own fallback approximation after a failed solve
        ref = np.array([fa_h, fa_v, -fb_h, -fb_v])
        mine = np.array([sol.h_anchor, sol.v_anchor, sol.h, sol.v_top], dtype=float)
        if info["ProfileType"] == 6:
            # MoorPy's vertical branch returns magnitudes; ours keep the sign convention of
            # the general case (V_top - V_anchor = w L)
            ref, mine = np.abs(ref), np.abs(mine)
            assert float(sol.v_top - sol.v_anchor) == pytest.approx(weight * length,
                                                                    rel=1e-9)
        scale = np.abs(ref).max()
        np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-5 * scale,
                                   err_msg=f"case {(x, z, length, weight, ea, seabed, mu)}")
        assert float(sol.grounded_length) == pytest.approx(info["LBot"], rel=0,
                                                           abs=1e-5 * length)
        compared += 1
        regimes.add(int(sol.regime))
    assert compared >= 300
    assert regimes == set(REGIMES)


def test_vectorised_matches_scalar_and_broadcasts():
    x = np.linspace(5.0, 95.0, 7)[:, None]
    z = np.array([0.0, 10.0, 40.0])[None, :]
    sol = solve_line(x, z, 100.0, 20.0, ea=1e6, seabed_friction=0.4)
    assert sol.h.shape == (7, 3) and sol.stiffness.shape == (7, 3, 2, 2)
    for i in range(7):
        for j in range(3):
            one = solve_line(float(x[i, 0]), float(z[0, j]), 100.0, 20.0, ea=1e6,
                             seabed_friction=0.4)
            # vectorised solves warm-start from the previous element: same root, last bits
            assert float(one.h) == pytest.approx(sol.h[i, j], rel=1e-11, abs=1e-9)
            assert float(one.v_top) == pytest.approx(sol.v_top[i, j], rel=1e-11, abs=1e-9)
            assert float(one.h_anchor) == pytest.approx(sol.h_anchor[i, j], rel=1e-11,
                                                        abs=1e-9)


# --- relational checks ----------------------------------------------------------------------

@pytest.mark.parametrize("x, z, seabed, mu", [(60.0, 50.0, True, 0.0), (80.0, 30.0, True, 0.7),
                                              (20.0, -10.0, False, 0.0),
                                              (95.0, 0.0, True, 0.3)])
def test_split_line_equals_single_line(x, z, seabed, mu):
    one = solve_line(x, z, 100.0, 30.0, ea=2e5, seabed=seabed, seabed_friction=mu)
    two = solve(Line((Segment(37.0, 30.0, 2e5), Segment(63.0, 30.0, 2e5)), seabed=seabed,
                     seabed_friction=mu), x, z)
    for name in ("h", "v_top", "h_anchor", "v_anchor", "grounded_length"):
        assert float(getattr(two, name)) == pytest.approx(float(getattr(one, name)), rel=1e-10,
                                                          abs=1e-9)
    np.testing.assert_allclose(two.stiffness, one.stiffness, rtol=1e-8)


@pytest.mark.parametrize("x, z", [(70.0, 30.0), (50.0, 45.0), (85.0, 10.0)])
def test_friction_changes_anchor_tension_only(x, z):
    w, length = 25.0, 100.0
    free = solve_line(x, z, length, w)
    rough = solve_line(x, z, length, w, seabed_friction=0.5)
    assert float(free.grounded_length) > 0.0
    for name in ("h", "v_top", "grounded_length"):
        assert float(getattr(rough, name)) == pytest.approx(float(getattr(free, name)),
                                                            rel=1e-12)
    expected = max(0.0, float(free.h) - 0.5 * w * float(free.grounded_length))
    assert float(rough.h_anchor) == pytest.approx(expected, rel=1e-10, abs=1e-9)
    assert float(free.h_anchor) == pytest.approx(float(free.h), rel=1e-12)


@pytest.mark.parametrize("x, z, seabed", [(30.0, 20.0, False), (40.0, -5.0, False),
                                          (60.0, 30.0, True), (10.0, 60.0, False)])
def test_top_tension_is_bottom_tension_plus_weight_times_height(x, z, seabed):
    # seed 002 eqs 21/49 (no drag, inextensible): T_top = T_bottom + w * height; on a
    # seabed the bottom of the hanging part is the touchdown point, T = H, height = z
    w = 12.0
    sol = solve_line(x, z, 80.0, w, seabed=seabed)
    bottom = float(sol.h) if float(sol.grounded_length) > 0 else float(sol.t_anchor)
    assert float(sol.t_top) == pytest.approx(bottom + w * z, rel=1e-11)


# --- stiffness, regimes, profile ------------------------------------------------------------

@pytest.mark.parametrize("x, z, ea, seabed, mu", [
    (30.0, 20.0, math.inf, False, 0.0), (60.0, 40.0, 1e6, True, 0.0),
    (80.0, 20.0, 5e5, True, 0.5), (20.0, -15.0, 1e5, False, 0.0),
    (99.0, 5.0, 1e7, True, 0.0)])
def test_stiffness_matches_central_differences(x, z, ea, seabed, mu):
    line = Line.homogeneous(100.0, 40.0, ea, seabed, mu)
    k = solve(line, x, z).stiffness
    d = 1e-5
    fx = [solve(line, x + s * d, z) for s in (1, -1)]
    fz = [solve(line, x, z + s * d) for s in (1, -1)]
    fd = np.array([[(fx[0].h - fx[1].h) / (2 * d), (fz[0].h - fz[1].h) / (2 * d)],
                   [(fx[0].v_top - fx[1].v_top) / (2 * d), (fz[0].v_top - fz[1].v_top) / (2 * d)]],
                  dtype=float)
    np.testing.assert_allclose(k, fd, rtol=2e-5, atol=1e-6 * np.abs(fd).max())
    assert k[0, 1] == pytest.approx(k[1, 0], rel=1e-9)  # conservative: symmetric


def test_regimes_slack_vertical_taut():
    piled = solve_line(10.0, 30.0, 100.0, 50.0)
    assert REGIMES[int(piled.regime)].startswith("slack")
    assert float(piled.h) == 0.0 and float(piled.v_top) == pytest.approx(50.0 * 30.0)
    assert float(piled.grounded_length) == pytest.approx(70.0)
    vertical = solve_line(0.0, 30.0, 50.0, 10.0, seabed=False)  # folded U below the anchor
    assert float(vertical.h) < 1e-6
    # inextensible fold: 40 m hang from the fairlead down to the bottom of the U and 10 m up
    # to the anchor, i.e. V_top = 40 w
    assert float(vertical.v_top) == pytest.approx(400.0, rel=1e-6)
    near_taut = solve_line(60.0, 79.99, 100.0, 10.0)
    assert float(near_taut.t_top) > 1e4
    with pytest.raises(ValueError, match="impossible geometry"):
        solve_line(60.0, 80.0, 100.0, 10.0)
    # an elastic line reaches past its unstretched length: mean tension above EA * strain
    # (sag takes up some of the stretch), top tension below that plus the whole weight
    stretched = solve_line(60.0, 80.5, 100.0, 10.0, ea=1e6)
    strain_tension = 1e6 * (math.hypot(60.0, 80.5) / 100.0 - 1.0)
    assert strain_tension < float(stretched.t_top) < strain_tension + 10.0 * 100.0 + 1500.0


@pytest.mark.parametrize("kwargs, match", [
    (dict(span=math.nan, height=1.0), "span"), (dict(span=1.0, height=math.inf), "height"),
    (dict(span=-1.0, height=1.0), "span"), (dict(span=1.0, height=-1.0), "seabed")])
def test_bad_inputs_are_clear_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        solve_line(length=50.0, weight=10.0, **kwargs)
    with pytest.raises(ValueError, match=match):
        solve_line(np.array([kwargs["span"], 1.0]), kwargs["height"], 50.0, 10.0)


def test_wrong_types_are_clear_errors():
    with pytest.raises(ValueError, match="span must be numeric"):
        solve_line("far", 10.0, 50.0, 10.0)
    with pytest.raises(ValueError, match="segment weight must be a number"):
        Segment(10.0, "heavy")
    with pytest.raises(ValueError, match="broadcast"):
        solve_line(np.ones(3), np.ones(2), 50.0, 10.0)


@pytest.mark.parametrize("bad", [dict(length=0.0, weight=1.0), dict(length=1.0, weight=math.nan),
                                 dict(length=1.0, weight=1.0, ea=-5.0)])
def test_bad_segments_are_clear_errors(bad):
    with pytest.raises(ValueError, match="segment"):
        Segment(**bad)
    with pytest.raises(ValueError, match="seabed_friction"):
        Line.homogeneous(10.0, 1.0, seabed_friction=-0.1)
    with pytest.raises(ValueError, match="Joint"):
        Line((Segment(1.0, 1.0), Segment(1.0, 1.0)), (Joint(), Joint()))


@pytest.mark.parametrize("x, z, seabed, mu", [(60.0, 40.0, True, 0.6), (30.0, 10.0, False, 0.0),
                                              (15.0, 30.0, True, 0.0)])
def test_profile_ends_and_tension(x, z, seabed, mu):
    sol = solve_line(x, z, 100.0, 20.0, ea=3e5, seabed=seabed, seabed_friction=mu)
    p = sol.profile(41)
    assert p.s[0] == 0.0 and p.s[-1] == 100.0
    assert (p.x[0], p.z[0]) == (0.0, 0.0)
    assert p.x[-1] == pytest.approx(x, abs=1e-8) and p.z[-1] == pytest.approx(z, abs=1e-8)
    assert p.tension[-1] == pytest.approx(float(sol.t_top), rel=1e-9)
    assert p.tension[0] == pytest.approx(float(sol.t_anchor), rel=1e-9, abs=1e-9)
    assert np.all(p.z >= -1e-9) if seabed else p.z.min() < 0.0


def test_multisegment_joint_tensions_and_point_loads():
    # chain 50 m (100 N/m) + clump 500 N + rope 50 m (10 N/m), fully suspended
    line = Line((Segment(50.0, 100.0), Segment(50.0, 10.0)), (Joint(500.0),), seabed=False)
    sol = solve(line, 60.0, 60.0)
    v_top = float(sol.v_top)
    # vertical tension just above the clump = top minus the rope's weight
    assert float(sol.joint_v[0]) == pytest.approx(v_top - 500.0, rel=1e-12)
    assert float(sol.v_anchor) == pytest.approx(v_top - 500.0 - 500.0 - 5000.0, rel=1e-12)
    assert float(sol.joint_tension[0]) == pytest.approx(math.hypot(float(sol.h), v_top - 500.0))
    p = sol.profile(101)
    assert p.x[-1] == pytest.approx(60.0, abs=1e-8) and p.z[-1] == pytest.approx(60.0, abs=1e-8)
