"""Motion -> tension estimator: quasi-static limit, dynamic increments, flags, state, IMU path."""

import contextlib
import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from models import waves
from models.dynamics import ElasticDragCord, axial_impedance, drag_constant
from models.estimator import (
    CatenaryQuasiStatic,
    EstimatorConfig,
    EstimatorState,
    Flag,
    LinearisedQuasiStatic,
    MotionTensionEstimator,
    catenary_estimator,
    seed004_estimator,
    simulate_tension,
)
from models.estimator import _force_flags
from models.catenary import solve, vaps_mooring

SHARED = next(
    (p / "shared" for p in Path(__file__).resolve().parents if (p / "shared/realdata").is_dir()),
    None,
)
DT = 0.05
# Stand-in quasi-static model: a taut-ish line with top angle atan(6/8) at rest.
QS = LinearisedQuasiStatic(h0=8000.0, v0=6000.0, k_hx=4000.0, k_hz=1500.0, k_vx=1500.0, k_vz=3000.0,
                           x_range=(-10.0, 10.0), z_range=(-5.0, 5.0))
CORD = ElasticDragCord(c=drag_constant(1.2, 0.031, 1000.0), span=30.0, alpha=0.1, axial_stiffness=3.43e6)


def config(**kw):
    base = dict(dt=DT, span=30.0, height=23.0, line_length=40.0, mass_per_length=1.1, ea=3.43e6,
                axial_model="finite", drag=CORD, flat_cord_max_deg=60.0)
    base.update(kw)
    return EstimatorConfig(**base)


def test_slow_heave_reproduces_quasi_static():
    t = np.arange(0, 1200, DT)
    heave = 1.5 * np.sin(2 * np.pi * t / 600)
    surge = 0.8 * np.sin(2 * np.pi * t / 900)
    est = simulate_tension(heave, surge, np.zeros_like(t), config(), QS)
    ref, _, _, _ = QS(surge, heave)
    np.testing.assert_allclose(est.quasi_static, ref, rtol=1e-12)
    # The dynamic parts vanish for slow motion: within 0.05 % of the quasi-static tension.
    np.testing.assert_allclose(est.tension, ref, rtol=5e-4)
    assert np.all(est.flags[2:] == 0)


def test_axial_increments_match_seed002_forms():
    t = np.arange(0, 60, DT)
    w = 2 * np.pi / 6.0
    heave = 0.5 * np.sin(w * t)
    angle = math.atan2(6000.0, 8000.0)
    # Infinite line: Z x (W sin(alpha)) with W the heave speed (backward difference).
    est = simulate_tension(heave, 0 * t, 0 * t, config(axial_model="infinite", drag=None), QS)
    v = np.diff(heave, prepend=heave[0]) / DT
    _, h, vv, _ = QS(0 * t, heave)
    expect = axial_impedance(3.43e6, 1.1) * v * vv / np.hypot(h, vv)
    np.testing.assert_allclose(est.axial, expect, rtol=1e-12, atol=1e-9)
    peak = axial_impedance(3.43e6, 1.1) * 0.5 * w * math.sin(angle)
    assert np.max(est.axial) == pytest.approx(peak, rel=0.02)
    # Finite (short) line: (m L / 3) x tangential acceleration, amplitude m L/3 a w^2 sin(alpha).
    est = simulate_tension(heave, 0 * t, 0 * t, config(axial_model="finite", drag=None), QS)
    a = np.diff(heave, n=2, prepend=[heave[0], heave[0]]) / DT**2
    np.testing.assert_allclose(est.axial, 1.1 * 40 / 3 * a * vv / np.hypot(h, vv), rtol=1e-9, atol=1e-9)
    # At the trough (heave -0.5 m: H = 7250 N, V = 4500 N) the increment is m L/3 a w^2 sin(top angle).
    peak = 1.1 * 40 / 3 * 0.5 * w**2 * 4500 / math.hypot(7250, 4500)
    assert np.max(est.axial[10:]) == pytest.approx(peak, rel=0.01)


def test_drag_increment_steady_separation():
    # Fairlead moving away horizontally at 0.4 m/s: chord speed Vz = 0.4 cos(chord angle);
    # in steady state the form speed V = Vz and dT = k Vz^2 (seed 001 eq 46).
    t = np.arange(0, 40, DT)
    surge = 0.4 * t
    est = simulate_tension(0 * t, surge, 0 * t, config(axial_model="none"), QS)
    xs = 30.0 + surge[-1]
    vz = 0.4 * xs / math.hypot(xs, 23.0)
    assert est.drag[-1] == pytest.approx(CORD.tension_coefficient * vz**2, rel=1e-3)
    # Moving back in: the line unloads by the same law.
    est2 = simulate_tension(0 * t, -0.4 * t / 4, 0 * t, config(axial_model="none"), QS)
    assert est2.drag[-1] < 0


def test_blocks_equal_batch_and_state_round_trip():
    m = waves.buoy_motion(1.5, 6.0, 300.0, DT, seed=11, depth=23.0, direction_deg=25.0)
    cfg = config()
    batch = simulate_tension(m.heave, m.surge, m.sway, cfg, QS)
    est = MotionTensionEstimator(cfg, QS)
    parts = []
    for i in range(0, m.t.size, 20):
        if i == 2000:  # checkpoint through JSON and continue in a new object
            saved = json.loads(json.dumps(est.state.to_dict()))
            est = MotionTensionEstimator(cfg, QS, EstimatorState.from_dict(saved))
        parts.append(est.update(m.heave[i : i + 20], m.surge[i : i + 20], m.sway[i : i + 20]).tension)
    np.testing.assert_allclose(np.concatenate(parts), batch.tension, rtol=1e-12)
    # The dynamic parts are a real contribution in a 1.5 m sea, not noise.
    assert np.std(batch.drag) > 0.05 * np.std(batch.quasi_static)


def test_heading_rotation():
    t = np.arange(0, 30, DT)
    r = 2.0 * np.sin(2 * np.pi * t / 8)
    a = simulate_tension(0 * t, r, 0 * t, config(), QS).tension
    # The same motion reported in a frame rotated by 90 deg: x_body = -y_moor... rotate back.
    b = MotionTensionEstimator(config(), QS).update(0 * t, 0 * t, -r, heading_deg=90.0).tension
    np.testing.assert_allclose(b, a, rtol=1e-9)


def test_flags():
    t = np.arange(0, 10, DT)
    # Large inward offset: H and V < 0 in the linear model -> SLACK and zero tension.
    est = simulate_tension(0 * t, -5.0 + 0 * t, 0 * t, config(), QS)
    assert np.all(est.flags & Flag.SLACK) and np.all(est.tension == 0)
    # Outside the calibrated range.
    est = simulate_tension(0 * t, 12.0 + 0 * t, 0 * t, config(), QS)
    assert np.all(est.flags & Flag.OUT_OF_RANGE)
    # Steep line (top angle 36.9 deg > 30 deg limit) with the jerk model on -> FLAT_CORD.
    est = simulate_tension(0 * t, 0 * t, 0 * t, config(flat_cord_max_deg=30.0), QS)
    assert np.all(est.flags & Flag.FLAT_CORD)
    # Fresh stream: the first two samples have no velocity history.
    est = simulate_tension(0 * t, 0 * t, 0 * t, config(), QS)
    np.testing.assert_array_equal(est.flags[:3], [Flag.SETTLING, Flag.SETTLING, 0])
    with pytest.raises(ValueError, match="heave contains NaN"):
        simulate_tension(np.r_[0.0, np.nan], np.zeros(2), np.zeros(2), config(), QS)
    with pytest.raises(ValueError, match="sway has 1 samples"):
        simulate_tension(np.zeros(2), np.zeros(2), np.zeros(1), config(), QS)
    with pytest.raises(ValueError, match="axial_model"):
        config(axial_model="bogus")


@pytest.fixture(scope="module")
def vaps():
    return seed004_estimator(dt=DT)


def test_slow_motion_reproduces_catenary_seed004(vaps):
    cfg, qs = vaps
    t = np.arange(0, 1200, DT)
    heave = 1.5 * np.sin(2 * np.pi * t / 600)
    surge = 2.0 * np.sin(2 * np.pi * t / 900)
    sway = 1.0 * np.cos(2 * np.pi * t / 700)
    est = simulate_tension(heave, surge, sway, cfg, qs)
    # Exact catenary solve at the instantaneous fairlead position (span includes sway).
    span = np.hypot(cfg.span + surge, sway)
    exact = solve(vaps_mooring(), span[::50], 23.0 + heave[::50]).t_top
    np.testing.assert_allclose(est.quasi_static[::50], exact, rtol=1e-3)
    # Slow motion: the dynamic increments are below 1 % of the quasi-static tension.
    np.testing.assert_allclose(est.tension[2:], est.quasi_static[2:], rtol=0.01)
    # The floated VAPS line lifts its anchor by ~575 N at rest: below the 1000 N limit.
    assert not np.any(est.flags[2:] & (Flag.SLACK | Flag.OUT_OF_RANGE | Flag.ANCHOR_LIFTED))


def _quasi_static_numpy(qs, x_offset, z_heave):
    """CatenaryQuasiStatic as first written in numpy (the reference of its compiled flags)."""
    x0, x1, z0, z1 = qs._box
    xs, zs = qs.span + x_offset, qs.height + z_heave
    xc, zc = np.clip(xs, x0, x1), np.clip(zs, z0, z1)
    f = qs.table.forces(xc, zc)
    flags = ((xc != xs) | (zc != zs)).astype(np.uint8) * np.uint8(Flag.OUT_OF_RANGE)
    flags |= (f.h <= 0.0).astype(np.uint8) * np.uint8(Flag.SLACK)
    lifted = f.v - qs._line_weight > qs.anchor_uplift_limit_N
    flags |= lifted.astype(np.uint8) * np.uint8(Flag.ANCHOR_LIFTED)
    return f.t, f.h, f.v, flags


@pytest.mark.parametrize("plain", [False, True])
def test_catenary_quasi_static_equals_the_numpy_form(vaps, plain):
    # inside, on and beyond every edge of the table (clamped, OUT_OF_RANGE), slack and
    # anchor-lifting positions, broadcast shapes; NaN is outside (the table's error)
    _, qs = vaps
    from models import _jit

    x0, x1, z0, z1 = qs._box
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(x0 - 2, x1 + 2, 3000) - qs.span,
                        [x0 - qs.span, x1 - qs.span, -qs.span, np.inf, -np.inf]])
    z = np.concatenate([rng.uniform(z0 - 2, z1 + 2, 3000) - qs.height,
                        [z0 - qs.height, z1 - qs.height, 0.0, 0.0, 0.0]])
    lifting = CatenaryQuasiStatic(qs.table, qs.span, qs.height, 300.0)  # lifts at rest
    with _jit.uncompiled() if plain else contextlib.nullcontext():
        for model in (qs, lifting):
            got, ref = model(x, z), _quasi_static_numpy(model, x, z)
            for a, b in zip(got, ref):
                np.testing.assert_array_equal(a, b)
            assert got[3].dtype == np.uint8 and got[3].shape == x.shape
            assert np.any(got[3] == Flag.OUT_OF_RANGE | Flag.ANCHOR_LIFTED)
        assert not np.all(qs(x, z)[3] & Flag.ANCHOR_LIFTED)  # (lifting: every sample)
        # broadcast: one heave for every offset, and a 2-D block
        for a, b in zip(qs(x[:50], 0.25), _quasi_static_numpy(qs, x[:50], 0.25)):
            np.testing.assert_array_equal(a, b)
        grid = (x[:60].reshape(6, 10), z[:60].reshape(6, 10))
        for a, b in zip(qs(*grid), _quasi_static_numpy(qs, *grid)):
            np.testing.assert_array_equal(a, b)
        with pytest.raises(ValueError, match="NaN counts as outside"):
            qs(np.array([0.0, np.nan]), np.zeros(2))
        with pytest.raises(ValueError, match="NaN counts as outside"):
            qs(np.zeros(2), np.array([np.nan, 0.0]))
        # the slack column (H <= 0) lies outside this table: the flags by hand
        flags = np.array([0, 8, 0, 0, 8], np.uint8)
        _force_flags(np.array([-1.0, 0.0, 1e-300, 5.0, 5.0]),
                     np.array([0.0, 0.0, 10.0, 10.0 + 300.0, 10.0 + 300.5]), 10.0, 300.0, flags)
        np.testing.assert_array_equal(flags, [1, 9, 0, 0, 10])


def test_seed004_flags_and_dynamics_in_waves(vaps):
    cfg, qs = vaps
    # Off the table: clamped and flagged.
    _, _, _, f = qs(np.array([10.0, 0.0]), np.array([0.0, 0.0]))
    assert f[0] & Flag.OUT_OF_RANGE and not f[1] & Flag.OUT_OF_RANGE
    # The field-failure sea (Hs 1.5 m, Tp 5.25 s): drag dominates the dynamic increment and
    # the line snaps slack at times; tensions stay within the WAVFOR bound (7.2 kN).
    m = waves.buoy_motion(1.5, 5.25, 600.0, DT, seed=1, depth=23.0)
    est = simulate_tension(m.heave, m.surge, m.sway, cfg, qs)
    assert np.std(est.drag) > 2 * np.std(est.axial) > 0
    assert 0.0 < np.mean((est.flags & Flag.SLACK) > 0) < 0.3
    assert np.max(est.tension) < 7230.0
    # Stiffer lines are the estimator's: the seed-004 line is flat enough for the jerk model.
    assert not np.any(est.flags & Flag.FLAT_CORD)


def test_imu_path_matches_displacement_path():
    m = waves.buoy_motion(1.5, 7.0, 1800.0, DT, seed=5, depth=23.0, direction_deg=10.0)
    cfg = config(imu_f_cut=0.02)
    est = MotionTensionEstimator(cfg, QS)
    out = [
        est.update_accel(m.accel_x[i : i + 20], m.accel_y[i : i + 20], m.accel_z[i : i + 20])
        for i in range(0, m.t.size, 20)
    ]
    tension = np.concatenate([o.tension for o in out])
    flags = np.concatenate([o.flags for o in out])
    ref = simulate_tension(m.heave, m.surge, m.sway, cfg, QS).tension
    settled = (flags & Flag.SETTLING) == 0
    assert settled.sum() == m.t.size - int(4 / 0.02 / DT)
    # The integrator's phase lead shifts samples but keeps the load ranges: std within 5 %.
    assert np.std(tension[settled]) == pytest.approx(np.std(ref[settled]), rel=0.05)
    assert np.mean(tension[settled]) == pytest.approx(np.mean(ref[settled]), rel=0.01)


def test_wanted_samples_only_are_estimated_exactly(vaps):
    # the pipeline asks only for the samples that feed fatigue: those must be bit-identical
    # to a full estimate, the rest NaN, and the stream state must advance the same
    cfg, qs = vaps
    m = waves.buoy_motion(1.5, 5.25, 120.0, DT, seed=2, depth=23.0)
    full, part = MotionTensionEstimator(cfg, qs), MotionTensionEstimator(cfg, qs)
    rng = np.random.default_rng(0)
    for i in range(0, m.t.size, 40):
        sl = slice(i, i + 40)
        want = rng.random(m.accel_z[sl].size) < 0.3
        a = full.update_accel(m.accel_x[sl], m.accel_y[sl], m.accel_z[sl])
        if i % 80:  # every other block compact: the wanted samples' estimates only
            c = part.update_accel(m.accel_x[sl], m.accel_y[sl], m.accel_z[sl], want=want,
                                  compact=True)
            for got, ref in zip(dataclasses.astuple(c), dataclasses.astuple(a)):
                np.testing.assert_array_equal(got, ref[want])
            assert c.flags.dtype == np.uint8
            continue
        b = part.update_accel(m.accel_x[sl], m.accel_y[sl], m.accel_z[sl], want=want)
        np.testing.assert_array_equal(b.tension[want], a.tension[want])
        np.testing.assert_array_equal(b.flags[want], a.flags[want])
        np.testing.assert_array_equal(b.quasi_static[want], a.quasi_static[want])
        np.testing.assert_array_equal(b.axial[want], a.axial[want])
        np.testing.assert_array_equal(b.top_angle[want], a.top_angle[want])
        np.testing.assert_array_equal(b.drag, a.drag)  # the jerk ODE runs over every sample
        assert np.isnan(b.tension[~want]).all() and np.isnan(b.quasi_static[~want]).all()
        assert np.isnan(b.top_angle[~want]).all() and (b.axial[~want] == 0).all()
        # the first samples settle, the others carry no flags
        assert ((b.flags[~want] & ~np.uint8(Flag.SETTLING)) == 0).all()
    assert part.state.to_dict() == full.state.to_dict()
    # displacements, compact, the first block settling (its first two samples SETTLING)
    full, part = MotionTensionEstimator(cfg, qs), MotionTensionEstimator(cfg, qs)
    want = np.arange(40) % 3 == 1
    for sl in (slice(0, 40), slice(40, 80)):
        a = full.update(m.heave[sl], m.surge[sl], m.sway[sl])
        c = part.update(m.heave[sl], m.surge[sl], m.sway[sl], want=want, compact=True)
        for got, ref in zip(dataclasses.astuple(c), dataclasses.astuple(a)):
            np.testing.assert_array_equal(got, ref[want])
    assert part.state.to_dict() == full.state.to_dict()
    with pytest.raises(ValueError, match="want must be a boolean mask of 3 samples"):
        part.update(np.zeros(3), np.zeros(3), np.zeros(3), want=np.ones(2, bool))


def test_a_compact_estimate_of_every_sample_survives_the_next_update(vaps):
    # every sample wanted: the returned drag must not be the memory kept for the next block
    cfg, qs = vaps
    m = waves.buoy_motion(1.5, 5.25, 120.0, DT, seed=2, depth=23.0)
    full, part = MotionTensionEstimator(cfg, qs), MotionTensionEstimator(cfg, qs)
    want = np.ones(40, bool)
    held = []
    for sl in (slice(0, 40), slice(40, 80), slice(80, 120)):
        ref = full.update(m.heave[sl], m.surge[sl], m.sway[sl])
        held.append((ref, part.update(m.heave[sl], m.surge[sl], m.sway[sl], want=want,
                                      compact=True)))
    for ref, got in held:
        assert np.abs(ref.drag).max() > 0  # (the drag model is on)
        for g, r in zip(dataclasses.astuple(got), dataclasses.astuple(ref)):
            np.testing.assert_array_equal(g, r)


@pytest.mark.skipif(SHARED is None, reason="../shared/realdata absent")
def test_real_spotter_record_through_seed004(vaps):
    """Measured motion of a moored Spotter (2.5 Hz, mm): one hour of the clean window gives a
    calm-sea tension near the static value; the record's +/-10 m spike burst is flagged."""
    cfg, qs = vaps
    cfg25 = dataclasses.replace(cfg, dt=0.4)
    path = SHARED / "realdata/spotter_clallam_1945/0026_FLT.CSV"
    clean = np.genfromtxt(path, delimiter=",", skip_header=466, max_rows=9000, usecols=(2, 3, 4))
    x, y, z = clean.T / 1000.0
    assert waves.sea_state_from_heave(z, 0.4).hs == pytest.approx(0.41, abs=0.02)
    est = simulate_tension(z, x, y, cfg25, qs)
    static = float(qs(np.zeros(1), np.zeros(1))[0][0])
    assert np.median(est.tension) == pytest.approx(static, rel=0.05)
    assert np.all(np.isfinite(est.tension)) and not np.any(est.flags[2:])
    spikes = np.genfromtxt(path, delimiter=",", skip_header=184700, max_rows=200, usecols=(2, 3, 4))
    x, y, z = spikes.T / 1000.0
    est = simulate_tension(z, x, y, cfg25, qs)
    big = np.abs(z) > 5.0
    assert big.any() and np.all(est.flags[big] & Flag.OUT_OF_RANGE)


def test_catenary_estimator_options_and_errors():
    line = vaps_mooring()
    with pytest.raises(ValueError, match="nearly straight"):
        catenary_estimator(line, 33.0, 23.0, DT, 1.1, 1.2, 0.031, x_range=(-1, 0.3),
                           z_range=(-1, 0.5), table_rtol=1e-2)
    cfg, _ = catenary_estimator(line, 33.0, 23.0, DT, 1.1, 1.2, 0.031, x_range=(-1, 0.3),
                                z_range=(-1, 0.5), jerk=False, table_rtol=1e-2)
    assert cfg.drag is None
    # Series stiffness of the three segments (bridle rod much stiffer than the cable).
    comp = sum(s.length / s.ea for s in line.segments)
    assert cfg.ea == pytest.approx(40.0 / comp)
    with pytest.raises(ValueError, match="needs a finite ea"):
        config(ea=math.inf, axial_model="infinite")


@pytest.mark.parametrize("jerk", [True, False])
def test_imu_integrated_in_the_estimator_loop_equals_the_integrator(vaps, jerk):
    # heading None integrates inside the estimator's loop (in chunks of 256 samples, the
    # next chunk integrated beside the jerk steps); a heading (0 deg: the identity rotation)
    # goes through models.imu.DisplacementIntegrator.update first: the same bits, for blocks
    # of one sample, of a chunk and around it, of several chunks, with and without jerk
    cfg, qs = vaps
    if not jerk:
        cfg = dataclasses.replace(cfg, drag=None)
    m = waves.buoy_motion(1.5, 5.25, 300.0, DT, seed=4, depth=23.0, direction_deg=30.0)
    fused, separate = MotionTensionEstimator(cfg, qs), MotionTensionEstimator(cfg, qs)
    i = 0
    for size in itertools.cycle([777, 1, 2, 255, 256, 257, 513]):
        if i >= m.t.size:
            break
        sl = slice(i, i + size)
        a = fused.update_accel(m.accel_x[sl], m.accel_y[sl], m.accel_z[sl])
        b = separate.update_accel(m.accel_x[sl], m.accel_y[sl], m.accel_z[sl], heading_deg=0.0)
        for x, y in zip(dataclasses.astuple(a), dataclasses.astuple(b)):
            np.testing.assert_array_equal(x, y)
        i += size
    assert fused.state.to_dict() == separate.state.to_dict()
    if not jerk:
        assert not np.any(a.drag)
        return
    assert np.isfinite(a.tension).all() and np.std(a.drag) > 0
    # a NaN acceleration is named and changes nothing
    before = fused.state.to_dict()
    bad = m.accel_y[:50].copy()
    bad[7] = np.nan
    with pytest.raises(ValueError, match="accel_y contains NaN"):
        fused.update_accel(m.accel_x[:50], bad, m.accel_z[:50])
    assert fused.state.to_dict() == before


@pytest.mark.parametrize("plain", [False, True])
def test_jerk_ode_side_by_side_equals_one_step_after_the_other(plain):
    # _jerk_chain runs a long block's ODE in four stretches side by side, the later three
    # from a guess, redone until they meet the guessed runs: the same bits as
    # models.dynamics' one-step-after-the-other loop, whether they meet at once (b = 30),
    # late or never (b tiny: the ODE barely forgets its start), or trivially (b = inf)
    from models import _jit
    from models.dynamics import _jerk_steps
    from models.estimator import _SIDE_BY_SIDE, _jerk_chain

    rng = np.random.default_rng(3)
    with _jit.uncompiled() if plain else contextlib.nullcontext():
        for n in (_SIDE_BY_SIDE - 1, _SIDE_BY_SIDE, 4099):
            t = np.arange(n) * 0.1
            vz = 0.4 * np.sin(2 * np.pi * t / 6.0) + 0.05 * rng.normal(size=n)
            for b, y0 in ((30.36, 0.02), (1e-9, -0.3), (math.inf, 0.0), (2.0, 0.0)):
                ys, ref = np.empty(n), np.empty(n)
                last = _jerk_chain(vz, ys, b, y0)
                ref_last = _jerk_steps(vz, b, y0, ref)
                np.testing.assert_array_equal(ys.view(np.int64), ref.view(np.int64))
                assert np.float64(last).view(np.int64) == np.float64(ref_last).view(np.int64)


def test_a_long_block_equals_the_same_samples_in_short_blocks(vaps):
    # one 6000-sample block (the jerk ODE side by side) against 30 blocks of 200 (one step
    # after the other), IMU and displacement inputs: every output and the state to the bit
    cfg, qs = vaps
    m = waves.buoy_motion(1.5, 5.25, 300.0, DT, seed=6, depth=23.0)
    one, many = MotionTensionEstimator(cfg, qs), MotionTensionEstimator(cfg, qs)
    whole = one.update_accel(m.accel_x, m.accel_y, m.accel_z)
    parts = [many.update_accel(m.accel_x[i:i + 200], m.accel_y[i:i + 200], m.accel_z[i:i + 200])
             for i in range(0, m.t.size, 200)]
    for a, b in zip(dataclasses.astuple(whole), zip(*map(dataclasses.astuple, parts))):
        np.testing.assert_array_equal(a, np.concatenate(b))
    assert one.state.to_dict() == many.state.to_dict()
    assert np.std(whole.drag) > 0
    one, many = MotionTensionEstimator(cfg, qs), MotionTensionEstimator(cfg, qs)
    whole = one.update(m.heave, m.surge, m.sway)
    parts = [many.update(m.heave[i:i + 200], m.surge[i:i + 200], m.sway[i:i + 200])
             for i in range(0, m.t.size, 200)]
    np.testing.assert_array_equal(whole.tension, np.concatenate([p.tension for p in parts]))
    np.testing.assert_array_equal(whole.drag, np.concatenate([p.drag for p in parts]))
    assert one.state.to_dict() == many.state.to_dict()
