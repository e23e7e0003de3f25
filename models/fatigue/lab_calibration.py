"""Seed 004's lab fatigue test as validation, and the S-N curve calibrated to it (issue 20).

Appendix 2 (c): a previously unstressed piece of the BIW cable, axial tension from an
eccentric cam, i.e. simple harmonic from 0 to F at 13.6 cycles/min:

    T(t) = F / 2 (1 - cos(2 pi f t)),   f = 13.6 / 60 Hz          (``cam_tension``)

Failures (#22 AWG opened): 8.9 kN at 25.0e3 cycles; 9.8 kN at 17.1e3 and 27.0e3 cycles
(4.4 kN / 25.7e3 and 6.7 kN / 6.5e3 ran out without a fault and are not failures).

Mean stress. A 0-to-F cycle has R = 0: stress range sigma(F) - sigma(0) = sigma(F) and mean
sigma(F) / 2. The shipped curve (``SNCurve.vaps_copper``) is applied to the range with no
mean-stress correction, as the seed does (its predicted-failure table sets the endurance stress
equal to the peak stress of a 0-to-F cycle). The calibrated curve is fitted to these R = 0
cycles with the same convention, so it holds for cycles whose mean is about half their range,
as a tension cycle from slack has; a cycle on a higher mean tension is not covered by the test.

Calibration method (``calibrate``): keep the shape of the reference curve (the seed's Marks
x 0.42 slopes, knees and endurance stress) and fit one factor on life, i.e. a shift delta of
every log10 a_i, by least squares in log10 N (the usual regression variable for fatigue lives):

    delta = mean_j (log10 N_obs,j - log10 N_ref(S_j))

The two load levels are only 10 % apart in stress, so the slope cannot be fitted from them;
the shape is the handbook's. Uncertainty: the sample standard deviation s of the residuals
(n - 1 = 2 degrees of freedom) and the standard error of delta, s / sqrt(n). The curve at
delta - 2 s (``design_curve``) is the usual mean-minus-two-standard-deviations design curve
(DNV-RP-C203 2.4.1); with three specimens it is indicative only.

Public API
----------
- ``LAB_FAILURES``: (load [N], cycles) of the three failures; ``LAB_RATE_HZ``
- ``cam_tension(peak_N, n_cycles, samples_per_cycle, rate_hz=LAB_RATE_HZ) -> (t_s, tension_N)``
- ``LabCalibration`` (frozen dataclass): delta, its standard error, s, residuals, curves
- ``calibrate(reference, stress_ranges_Pa, observed_cycles) -> LabCalibration``
- ``vaps_lab_calibration(reference=None) -> LabCalibration`` (the seed's cable, free twist, left lay)
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from models.helix import HelixCable, conductor_stress
from models.fatigue.sn_curve import SNCurve

LAB_RATE_HZ = 13.6 / 60.0
LAB_FAILURES: tuple[tuple[float, float], ...] = ((8.9e3, 25.0e3), (9.8e3, 17.1e3), (9.8e3, 27.0e3))


def cam_tension(peak_N: float, n_cycles: int, samples_per_cycle: int,
                rate_hz: float = LAB_RATE_HZ) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and tensions [N] of ``n_cycles`` cam cycles 0 -> ``peak_N`` -> 0 (App. 2 (c)).

    Starts and ends at zero tension; ``samples_per_cycle`` samples per cycle (>= 4).
    """
    if not (math.isfinite(peak_N) and peak_N > 0):
        raise ValueError(f"peak_N must be finite and > 0, got {peak_N!r}")
    if n_cycles < 1 or samples_per_cycle < 4:
        raise ValueError("need n_cycles >= 1 and samples_per_cycle >= 4")
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be finite and > 0, got {rate_hz!r}")
    phase = np.arange(n_cycles * samples_per_cycle + 1) / samples_per_cycle
    return phase / rate_hz, 0.5 * peak_N * (1.0 - np.cos(2.0 * np.pi * phase))


@dataclasses.dataclass(frozen=True)
class LabCalibration:
    """A reference curve shifted in log10 life to fit lab failures (module docstring)."""

    reference: SNCurve
    stress_ranges_Pa: np.ndarray
    observed_cycles: np.ndarray
    predicted_cycles: np.ndarray  # by the reference curve
    delta: float  # log10 life shift
    std_error: float  # standard error of delta
    residual_std: float  # s, n - 1 degrees of freedom

    @property
    def life_factor(self) -> float:
        """10**delta: calibrated over reference life at any stress."""
        return float(10.0 ** self.delta)

    def curve(self, name: str = "VAPS copper, lab calibrated (seed 004 App. 2)", **options) -> SNCurve:
        """The calibrated (mean) curve; ``options`` as for ``SNCurve.with_factors``."""
        return self._shifted(self.delta, name, options)

    def design_curve(self, name: str = "VAPS copper, lab calibrated, mean - 2 s", **options) -> SNCurve:
        """The mean - 2 s curve (indicative with three specimens)."""
        return self._shifted(self.delta - 2.0 * self.residual_std, name, options)

    def _shifted(self, delta: float, name: str, options: dict) -> SNCurve:
        log_a = tuple(a + delta for a in self.reference.log_a)
        return dataclasses.replace(self.reference, name=name, log_a=log_a, **options)


def calibrate(reference: SNCurve, stress_ranges_Pa, observed_cycles) -> LabCalibration:
    """Fit the log10-life shift of ``reference`` to failures at ``stress_ranges_Pa`` (>= 2)."""
    s = np.asarray(stress_ranges_Pa, dtype=np.float64)
    n_obs = np.asarray(observed_cycles, dtype=np.float64)
    if s.ndim != 1 or s.shape != n_obs.shape or s.size < 2:
        raise ValueError("need two equal-length 1-D arrays of at least two failures")
    if not (np.all(np.isfinite(s)) and np.all(s > 0) and np.all(np.isfinite(n_obs)) and np.all(n_obs > 0)):
        raise ValueError("stress ranges and cycles must be finite and positive")
    n_ref = reference.cycles_to_failure(s)
    if not np.all(np.isfinite(n_ref)):
        raise ValueError("a failure lies below the reference curve's cut-off: no finite life to fit")
    residuals = np.log10(n_obs) - np.log10(n_ref)
    sd = float(np.std(residuals, ddof=1))
    return LabCalibration(reference, s, n_obs, n_ref, float(residuals.mean()),
                          sd / math.sqrt(s.size), sd)


def vaps_lab_calibration(reference: SNCurve | None = None,
                         cable: HelixCable | None = None) -> LabCalibration:
    """``calibrate`` on the seed's three failures: stress ranges from the helix model of the
    BIW cable (free twist, left lay as built, seed 004 App. 4); reference ``vaps_copper()``."""
    cable = HelixCable.vaps_biw() if cable is None else cable
    reference = SNCurve.vaps_copper() if reference is None else reference
    loads = np.array([f for f, _ in LAB_FAILURES])
    ranges = conductor_stress(loads, cable, "left") - conductor_stress(0.0, cable, "left")
    return calibrate(reference, ranges, [n for _, n in LAB_FAILURES])
