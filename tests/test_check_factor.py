"""The check-factor test (monitor.check_factor): linear waves pass, horizontal glitches fail,
streaming equals batch for any block split with state save/restore."""

import json
import math

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st
from scipy.optimize import brentq

from models.waves import buoy_motion
from monitor.check_factor import MEMORY, CheckFactor, bound
from monitor.config import config_with, default_config
from monitor.qartod import CHECK, FAIL, StreamQC
from monitor.validate import StreamValidator

S = 1_000_000_000
G = 9.80665
RATE = (math.sqrt(G * 23.0),) * 3  # the shipped motion fields' max_rate_per_s in 23 m
RATE = (math.sqrt(G * 23.0),) * 3  # the shipped motion fields' max_rate_per_s in 23 m


def coth2(period: float, depth: float) -> float:
    """coth^2(k d), k from omega^2 = g k tanh(k d) by bracketing (independent of models.waves)."""
    w = 2 * math.pi / period
    k = brentq(lambda k: w * w - G * k * math.tanh(k * depth), 1e-9, 10.0, xtol=1e-15)
    return 1 / math.tanh(k * depth) ** 2


def flags_of(t_s, z, x, y, cuts=(), restore=False, depth=23.0, gap=5.0, rate=RATE):
    t = np.rint(np.asarray(t_s) * S).astype(np.int64)
    cf = CheckFactor(depth, 25.0, gap, rate)
    out = []
    for a, b in zip([0, *cuts], [*cuts, t.shape[0]]):
        if restore:  # as a saved state file has it
            cf = CheckFactor(depth, 25.0, gap, rate, state=json.loads(json.dumps(cf.state())))
        out.append(cf.check(t[a:b], z[a:b], x[a:b], y[a:b]))
    return np.concatenate(out)


def test_bound_is_coth_squared_of_the_longest_wave():
    # 25 s in the VAPS mooring's 23 m: k d = 0.393 (shallow water), coth^2 = 7.097
    assert bound(23.0, 25.0) == pytest.approx(coth2(25.0, 23.0), rel=1e-12)
    assert round(bound(23.0, 25.0), 3) == 7.097
    assert bound(4000.0, 25.0) == pytest.approx(1.0, abs=1e-9)  # deep water


def test_a_single_wave_passes_below_the_longest_period_and_fails_above():
    # a surface follower on one linear wave: horizontal = coth(kd) x vertical, 90 deg apart.
    # Over a 50 s window of part-periods the ratio swings about coth^2 (22 s: 4.85 .. 6.41
    # about 5.58; 27 s: 7.16 .. 9.44 about 8.22), so these pass or fail at every sample
    t = np.arange(0, 600, 0.4)
    for period, fails in ((8.0, False), (22.0, False), (27.0, True), (35.0, True)):
        w = 2 * math.pi / period
        c = math.sqrt(coth2(period, 23.0))
        f = flags_of(t, 0.5 * np.sin(w * t), 0.5 * c * np.cos(w * t), 0 * t)
        assert (f[:63] == 2).all() and f[63] != 2  # not evaluated for the first 25 s
        assert (f[63:] == 4).all() if fails else (f[63:] == 1).all(), period


def test_a_linear_sea_passes():
    # 3 h of JONSWAP sea (Hs 2 m, Tp 10 s) in 23 m, 30 deg off the mooring, at 2.5 Hz
    m = buoy_motion(2.0, 10.0, 3 * 3600, 0.4, seed=3, depth=23.0, direction_deg=30.0)
    f = flags_of(m.t, m.heave, m.surge, m.sway, cuts=[1000, 7777])
    assert (f[63:] == 1).all()


def test_a_horizontal_excursion_fails_at_once_and_for_a_window_after():
    # a calm sea (5 cm heave), then a 3 m sway step over 0.8 s at t = 200 s, back at 230 s
    t = np.arange(0, 400, 0.4)
    z = 0.05 * np.sin(2 * math.pi * t / 8)
    x = 0.05 * np.cos(2 * math.pi * t / 8)
    y = np.interp(t, [0, 200, 200.8, 230, 230.8, 400], [0, 0, 3, 3, 0, 0])
    f = flags_of(t, z, x, y)
    first = int(np.flatnonzero(f == 4)[0])
    assert t[first] == 200.4  # the step's first sample
    # the window holds the step back (its pairs end at 230.8 s) until 280.4 s, the last
    # violation; the fail lasts while less than 50 s have passed since: to 330.0 s
    last = int(np.flatnonzero(f == 4)[-1])
    assert t[last] == 330.0 and (f[last + 1:] == 1).all()
    assert (f[first:last + 1] == 4).all()


def sea_10hz(seconds: float):
    """One 8-s linear wave (heave 0.5 m, surge coth(kd) times it) at 10 Hz in 23 m."""
    t = np.arange(0, seconds, 0.1)
    w = 2 * math.pi / 8.0
    return t, 0.5 * np.sin(w * t), 0.5 * math.sqrt(coth2(8.0, 23.0)) * np.cos(w * t), 0 * t


def test_a_lone_spike_is_left_out_of_the_window():
    # an 8 m surge spike in one sample (80 m/s: no water particle moves faster than its
    # wave, sqrt(g d) = 15 m/s here), and a heave one with a NaN before the sea comes back.
    # The surge spike's own window violates, so it fails; the heave spike only adds vertical
    # motion (pass; the validator rejects both as spikes). Every other sample is judged as
    # if they were not there; without holding, the surge spike failed 100 s of sea around it
    t, z, x, y = sea_10hz(400)
    x[2000] += 8.0
    z[3000] -= 8.0
    x[3001] = np.nan
    f = flags_of(t, z, x, y)
    assert f[2000] == 4 and f[3000] == 1 and f[3001] == 9
    keep = np.ones(t.shape[0], bool)
    keep[[2000, 3000, 3001]] = False
    np.testing.assert_array_equal(f[keep], flags_of(t[keep], z[keep], x[keep], y[keep]))
    assert (f[keep][250:] == 1).all() and (f[:250] == 2).all()
    unheld = flags_of(t, z, x, y, rate=(math.inf,) * 3)
    assert (unheld == 4).sum() == 1000 and (unheld[2000:3000] == 4).all()


def test_a_fast_move_that_is_not_lone_is_taken_as_it_came():
    # a 6 m sway jump in one sample that stays 3 s, a surge spike of two samples, and a lone
    # one followed by a 10 s gap (the next sample cannot say): each is a real move here,
    # flagged exactly as by a test that holds nothing, and fails at once for 50 s and more
    t, z, x, y = sea_10hz(700)
    y[1000:1030] += 6.0
    x[3000:3002] += 8.0
    x[5000] += 8.0
    keep = (t < 500.05) | (t > 510.05)  # samples 5001 .. 5100 lost
    t, z, x, y = t[keep], z[keep], x[keep], y[keep]
    f = flags_of(t, z, x, y)
    np.testing.assert_array_equal(f, flags_of(t, z, x, y, rate=(math.inf,) * 3))
    for first in (1000, 3000, 5000):
        assert (f[first - 10:first] == 1).all() and (f[first:first + 500] == 4).all()


@pytest.mark.parametrize("restore", [False, True])
def test_a_held_sample_survives_a_block_end_and_a_restart(restore):
    t, z, x, y = sea_10hz(400)
    x[2000] += 8.0  # lone
    y[2500:2502] += 8.0  # not lone
    whole = flags_of(t, z, x, y)
    for cut in (2000, 2001, 2002, 2501, 2502, 2503):
        np.testing.assert_array_equal(flags_of(t, z, x, y, [cut], restore), whole)
    # the state holds the sample (time, heave, surge, sway) only while one is held
    cf = CheckFactor(23.0, 25.0, 5.0, RATE)
    tn = np.rint(t * S).astype(np.int64)
    cf.check(tn[:2001], z[:2001], x[:2001], y[:2001])
    assert cf.state()["held"] == [int(tn[2000]), z[2000], x[2000], y[2000]]
    cf.check(tn[2001:2002], z[2001:2002], x[2001:2002], y[2001:2002])
    assert "held" not in cf.state() and len(cf.state()["ints"]) == 7


def test_simulated_storm_motion_is_linear_waves_far_inside_the_bound(tmp_path):
    # the simulator's buoy in storm seas (buoymon simulate: 30 min each, 23 m): NDBC's
    # spectral check factor R(f) = (Sxx + Syy) / Szz tanh^2(k d) is 1 over the energetic
    # band (NDBC 96-01), and the windowed velocity ratio the test uses is the JONSWAP sea's
    # (differenced at 10 Hz, 2 cm of noise per channel: 1.326 / 1.514, computed here), far
    # inside C^2 = 7.10: no fail. (Steep-sea extras stay small: a 6 m, 12 s wave's Stokes
    # drift, 0.27 m/s at most, adds 0.07 m^2/s^2 to the 1.66 of the horizontal velocity.)
    from scipy import signal

    from models.waves import jonswap
    from replay.reader import LogReader
    from replay.simulate import SimConfig, simulate

    for hs, tp, want in ((4.0, 10.0, 1.326), (6.0, 12.0, 1.514)):
        log = tmp_path / f"hs{hs:g}.mcap"
        simulate(SimConfig(hours=0.5, hs_m=hs, tp_s=tp, seed=7), log)
        blocks = [b for b in LogReader(log) if b.sensor == "motion"]
        t = np.concatenate([b.t_ns for b in blocks]) * 1e-9
        z, x, y = (np.concatenate([b.fields[k] for b in blocks])
                   for k in ("heave_m", "surge_m", "sway_m"))
        f, szz = signal.welch(z, fs=10.0, nperseg=2560)
        sh = signal.welch(x, fs=10.0, nperseg=2560)[1] + signal.welch(y, fs=10.0, nperseg=2560)[1]
        band = (f > 0.6 / tp) & (f < 2.0 / tp)
        r = np.array([sh[i] / szz[i] / coth2(1 / f[i], 23.0) for i in np.flatnonzero(band)])
        weighted = float((r * szz[band]).sum() / szz[band].sum())
        assert abs(weighted - 1.0) < 0.01 and 0.9 < r.min() and r.max() < 1.05, (hs, weighted)
        # the theory: sum over the spectrum of |2 sin(pi f dt) / dt|^2 S(f) (coth^2 for the
        # horizontal) plus the noise's 2 sigma^2 / dt^2 per channel
        ff = np.linspace(0.01, 5.0, 5_000)
        d2 = (2 * np.sin(np.pi * ff * 0.1) / 0.1) ** 2 * jonswap(ff, hs, tp)
        c2 = np.array([coth2(1 / v, 23.0) if v < 1.0 else 1.0 for v in ff])  # deep above 1 Hz
        noise = 2 * 0.02 ** 2 / 0.01
        theory = ((np.trapezoid(d2 * c2, ff) + 2 * noise) / (np.trapezoid(d2, ff) + noise))
        assert theory == pytest.approx(want, abs=5e-4)
        vz2, vh2 = np.diff(z) ** 2, np.diff(x) ** 2 + np.diff(y) ** 2
        ratio = [vh2[i:i + 500].sum() / vz2[i:i + 500].sum() for i in range(0, vz2.size - 500, 50)]
        assert np.median(ratio) == pytest.approx(want, rel=0.03)
        assert max(ratio) < 2.1 < bound(23.0, 25.0) / 3
        flags = flags_of(t, z, x, y)
        assert (flags[:250] == 2).all() and (flags[250:] == 1).all()


def test_missing_samples_and_gaps():
    t = np.arange(0, 300, 0.4)
    z = 0.5 * np.sin(2 * math.pi * t / 8)
    x = 0.5 * np.cos(2 * math.pi * t / 8)
    z[100] = np.nan
    keep = (t < 100) | (t > 160)  # a 60 s gap: the window spans it
    f = flags_of(t[keep], z[keep], x[keep], 0 * x[keep])
    assert f[100] == 9 and (np.delete(f[63:], 100 - 63) == 1).all()


def record(n: int, seed: int):
    """A sea with horizontal glitches, NaNs and gaps, at 2.5 Hz."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(np.where(rng.random(n) < 0.01, rng.uniform(1, 80, n), 0.4))
    z = 0.3 * np.sin(t * 0.7) + rng.normal(0, 0.02, n)
    x = 0.3 * np.cos(t * 0.7) + rng.normal(0, 0.02, n)
    y = rng.normal(0, 0.02, n)
    for k in rng.integers(0, n - 30, n // 400):
        x[k:k + 25] += np.linspace(0, rng.uniform(-8, 8), 25)
    # lone spikes of 7-12 m: faster than sqrt(g d) (6 m in 0.4 s), held and left out
    k = rng.integers(1, n - 1, n // 300)
    x[k] += rng.choice((-1.0, 1.0), k.size) * rng.uniform(7, 12, k.size)
    z[rng.integers(0, n, n // 200)] = np.nan
    return t, z, x, y


@settings(max_examples=40, deadline=None)
@example(seed=0, cuts=[MEMORY - 5, MEMORY + 7], restore=True)  # restored across a wrap
@given(seed=st.integers(0, 10_000), cuts=st.lists(st.integers(1, 9_999), max_size=10),
       restore=st.booleans())
def test_streaming_equals_batch_for_any_block_split(seed, cuts, restore):
    t, z, x, y = record(10_000, seed)
    whole = flags_of(t, z, x, y)
    split = flags_of(t, z, x, y, sorted(set(cuts)), restore)
    np.testing.assert_array_equal(whole, split)
    assert (whole == 4).any() and (whole == 1).any() and (whole == 9).any()
    # the lone spikes were held (a test holding nothing flags otherwise)
    assert not np.array_equal(whole, flags_of(t, z, x, y, rate=(math.inf,) * 3))


def test_the_shipped_motion_stream_rejects_and_counts_it_by_name():
    cfg = default_config()
    assert cfg.validate["motion"].check_factor == (23.0, 25.0)
    t, z, x, y = record(3000, 5)
    z[np.isnan(z)] = 0.0
    tn = np.rint(t * S).astype(np.int64)
    v = StreamValidator("motion", cfg.validate["motion"])
    codes = v.check(tn, np.stack([z, x, y]), np.iinfo(np.int64).min)
    want = flags_of(t, z, x, y) == FAIL
    assert want.sum() > 100
    # every check-factor fail is rejected (as check_factor, or first as out_of_range etc.)
    assert (codes[want] != 0).all()
    assert v.qc_counts()["check_factor"] == {"suspect": 0, "fail": int(want.sum())}
    assert v.rejected["check_factor"] == int(np.count_nonzero(codes == 7))  # REASONS[6]
    assert v.rejected["check_factor"] > 0.9 * want.sum()
    # the StreamQC row equals the test's own flags; off for other streams
    qc = StreamQC(tuple(cfg.validate["motion"].fields.values()), check_factor=(23.0, 25.0, 5.0))
    flags, _ = qc.check(tn, np.stack([z, x, y]))
    np.testing.assert_array_equal(flags[CHECK] == FAIL, want)
    assert "check_factor" not in StreamValidator("tension", cfg.validate["tension"]).qc_counts()


@pytest.mark.parametrize("cuts", [[1], [700, 701, 2500], list(range(97, 3000, 331))])
def test_the_validator_streams_it_with_restarts(cuts):
    cfg = default_config()
    t, z, x, y = record(3000, 9)
    tn, values = np.rint(t * S).astype(np.int64), np.stack([z, x, y])
    never = np.iinfo(np.int64).min
    whole = StreamValidator("motion", cfg.validate["motion"])
    want = whole.check(tn, values, never)
    v, got = StreamValidator("motion", cfg.validate["motion"]), []
    for a, b in zip([0, *cuts], [*cuts, tn.shape[0]]):
        v = StreamValidator("motion", cfg.validate["motion"], json.loads(json.dumps(v.state())))
        got.append(v.check(tn[a:b], values[:, a:b], never))
    np.testing.assert_array_equal(np.concatenate(got), want)
    assert v.rejected == whole.rejected and v.qc_counts() == whole.qc_counts()
    assert whole.rejected["check_factor"] > 0


def test_switched_off_by_config():
    cfg = config_with(default_config(), validate={"motion": {"check_factor": False}})
    assert cfg.validate["motion"].check_factor is None
    assert "check_factor" not in StreamValidator("motion", cfg.validate["motion"]).qc_counts()
