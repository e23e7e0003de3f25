"""The simulator's ``wavfor`` load model: seed 004's held-fixed wave force in the time domain."""

import math

import numpy as np
import pytest

from models.waves import buoy_motion
from models.wavfor import morison_force, wavfor
from replay.reader import LogReader
from replay.simulate import SimConfig, simulate


def test_velocities_are_the_derivatives_of_the_displacements():
    m = buoy_motion(1.5, 5.25, 600.0, 0.05, seed=2, depth=23.0, direction_deg=30.0)
    n = len(m.heave)
    i_omega = 2j * np.pi * np.fft.rfftfreq(n, 0.05)

    def derivative(x):  # the records are periodic (one inverse FFT): exact spectral derivative
        return np.fft.irfft(i_omega * np.fft.rfft(x), n)

    for disp, vel, acc in ((m.heave, m.vel_z, m.accel_z), (m.surge, m.vel_x, m.accel_x),
                           (m.sway, m.vel_y, m.accel_y)):
        assert np.max(np.abs(derivative(disp) - vel)) < 1e-9 * np.max(np.abs(vel))
        assert np.max(np.abs(derivative(vel) - acc)) < 1e-9 * np.max(np.abs(acc))


def test_morison_force_at_crest_and_node_is_wavfor():
    """The refactored WAVFOR is the Morison force of its crest and node kinematics."""
    res = wavfor(1.52, 5.25)
    assert res.crest.vertical == pytest.approx(7230.1, abs=0.5)  # seed 004 App. 6: ~7.2 kN
    f = morison_force(0.0, 0.0, 1.0, -1.0)
    assert f.horizontal == pytest.approx(1000 * 1.8 * 3.3) and f.vertical == pytest.approx(-5940)
    with pytest.raises(ValueError, match="u must be finite"):
        morison_force(math.nan, 0.0, 0.0, 0.0)


def _tension(path):
    vals = [b.fields["tension_N"] for b in LogReader([path], coalesce=True) if b.sensor == "tension"]
    return np.concatenate(vals)


def test_wavfor_load_model_loads_the_cable_like_the_seed(tmp_path):
    """One hour of the demo storm: per-wave peaks of the order of WAVFOR's 7.2 kN for the
    significant wave, 0-to-F cycles (the line goes slack), the same sea as the catenary model."""
    cfg = dict(hours=0.5, hs_m=1.5, tp_s=5.25, seed=4, tension_noise_N=0.0)
    s_w = simulate(SimConfig(**cfg, load_model="wavfor"), tmp_path / "w.mcap")
    s_c = simulate(SimConfig(**cfg), tmp_path / "c.mcap")
    t = _tension(tmp_path / "w.mcap")
    assert s_w.load_model == "wavfor" and "wavfor load model" in s_w.text()
    assert t.min() == 0.0  # slack, never pushing
    assert 5e3 < np.percentile(t, 99) < 15e3
    assert t.max() < 3.0 * wavfor(1.5, 5.25).max_force
    # the catenary model's tension of the same sea is an order of magnitude smaller
    assert s_c.tension_N[1] * 2 < s_w.tension_N[1]
    with pytest.raises(ValueError, match="load_model = 'moorpy'"):
        SimConfig(**cfg, load_model="moorpy")
