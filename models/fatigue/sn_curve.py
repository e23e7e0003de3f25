"""S-N curves: cycles to failure and Miner damage per cycle for stress RANGES.

All stresses at this API are stress RANGES in Pa (peak to valley), and means in Pa;
curve parameters are kept in MPa as the standards print them. Every curve is held as
log-log linear segments N = 10**log_a_i * S**(-m_i) (S in MPa), the (m_i, log a_i)
convention of DNV-RP-C203, high-stress segment first, joined at knee stresses.

Forms
-----
- ``SNCurve.tabulated(stress_MPa, cycles, ...)``: log-log interpolation between table
  points. Above the highest stress the first segment is extended; below the lowest
  stress ``low_stress`` applies: ``"cutoff"`` (endurance limit: no damage),
  ``"miner"`` (elementary Miner: the last segment continues) or ``"haibach"`` (slope
  m' = 2m - 1 below the endurance stress).
- ``SNCurve.basquin(m, log_a)`` and ``SNCurve.multi_slope(m, log_a)``: knees at the
  intersections of consecutive segments; the last segment continues unless
  ``low_stress`` / ``endurance_MPa`` say otherwise.

Factors: ``scf`` multiplies the stress (stress concentration), ``derating`` divides the
curve's strength (equivalently multiplies the stress; seed 004 suggests >= 2 for field
conditions), ``dff`` multiplies the damage (design fatigue factor).

Mean-stress correction (``mean_correction``): ``"none"`` (default), ``"goodman"``
S / (1 - Sm/Su), ``"gerber"`` S / (1 - (Sm/Su)^2), ``"walker"`` S_ar = S_max^(1-g) S_a^g
with ``walker_gamma`` g, ``"swt"`` (Walker with g = 1/2). Corrections give no credit for
compressive mean; a mean at or above the ultimate strength ``ultimate_Pa`` gives infinite
damage (the part has failed statically); SWT/Walker give no damage when S_max <= 0.

Presets: ``vaps_copper()`` (seed 004, Marks annealed copper x 0.42),
``vaps_lab_calibrated()`` (the same shape fitted to seed 004's lab failures, models.fatigue.lab_calibration),
``dnv_rp_c203(detail, environment, knee)`` (DNV-RP-C203 Edition April 2016, Tables 2-1 air and
2-2 seawater with cathodic protection; the 2024 edition changed B1 to C2 and is not
tabulated here), ``dnv_chain_studless()`` (DNV-OS-E301 studless chain, m = 3,
a_D = 6.0e10, stress range in MPa on the nominal area).

Methods: ``cycles_to_failure(range_Pa, mean_Pa=None)``, ``damage_per_cycle(range_Pa,
mean_Pa=None, counts=1)`` (the (ranges, means, counts) order of ``StreamingRainflow.feed``),
``stress_range_at(cycles)`` (inverse, Pa, zero mean),
``to_dict()`` / ``from_dict()``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from functools import cached_property
from typing import Literal

import numpy as np

from models.fatigue import _loops


LowStress = Literal["miner", "cutoff", "haibach"]
MeanCorrection = Literal["none", "goodman", "gerber", "walker", "swt"]

_MPA = 1e6

# DNV-RP-C203 Edition April 2016. Table 2-1 (air): (m1, log a1, m2, log a2), knee at
# 1e7 cycles. Table 2-2 (seawater with cathodic protection): log a1 is lower (knee at
# 1e6 cycles), log a2 is the same as in air.
_DNV_2016_AIR = {
    "B1": (4.0, 15.117, 5.0, 17.146), "B2": (4.0, 14.885, 5.0, 16.856),
    "C": (3.0, 12.592, 5.0, 16.320), "C1": (3.0, 12.449, 5.0, 16.081),
    "C2": (3.0, 12.301, 5.0, 15.835), "D": (3.0, 12.164, 5.0, 15.606),
    "E": (3.0, 12.010, 5.0, 15.350), "F": (3.0, 11.855, 5.0, 15.091),
    "F1": (3.0, 11.699, 5.0, 14.832), "F3": (3.0, 11.546, 5.0, 14.576),
    "G": (3.0, 11.398, 5.0, 14.330), "W1": (3.0, 11.261, 5.0, 14.101),
    "W2": (3.0, 11.107, 5.0, 13.845), "W3": (3.0, 10.970, 5.0, 13.617),
}
_DNV_2016_SEAWATER_CP_LOG_A1 = {
    "B1": 14.917, "B2": 14.685, "C": 12.192, "C1": 12.049, "C2": 11.901, "D": 11.764,
    "E": 11.610, "F": 11.455, "F1": 11.299, "F3": 11.146, "G": 10.998, "W1": 10.861,
    "W2": 10.707, "W3": 10.570,
}

# Seed 004 section 8: Marks (1958) annealed copper endurance, x 0.42 (Faires 1955).
_MARKS_COPPER_MPA = (75.2, 78.0, 90.0, 106.0, 130.0)
_MARKS_COPPER_CYCLES = (1e7, 1e6, 1e5, 2.5e4, 1e4)
_FAIRES_COMBINED = 0.42


@dataclass(frozen=True)
class SNCurve:
    """Piecewise log-log S-N curve for stress ranges (see module docstring).

    ``m`` and ``log_a`` list the segments from high to low stress; ``knees_MPa`` (one
    fewer, descending) are the stress ranges where consecutive segments meet. Below
    ``endurance_MPa`` (if set) ``low_stress`` applies.
    """

    name: str
    m: tuple[float, ...]
    log_a: tuple[float, ...]
    knees_MPa: tuple[float, ...] = ()
    low_stress: LowStress = "miner"
    endurance_MPa: float | None = None
    scf: float = 1.0
    derating: float = 1.0
    dff: float = 1.0
    mean_correction: MeanCorrection = "none"
    ultimate_Pa: float | None = None
    walker_gamma: float = 0.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "m", tuple(float(v) for v in self.m))
        object.__setattr__(self, "log_a", tuple(float(v) for v in self.log_a))
        object.__setattr__(self, "knees_MPa", tuple(float(v) for v in self.knees_MPa))
        if len(self.m) == 0 or len(self.m) != len(self.log_a) or len(self.knees_MPa) != len(self.m) - 1:
            raise ValueError("SNCurve needs len(m) == len(log_a) >= 1 and one knee fewer than segments")
        if not all(np.isfinite(v) and v > 0 for v in self.m + self.knees_MPa):
            raise ValueError(f"SNCurve {self.name!r}: slopes and knees must be finite and positive")
        if not all(np.isfinite(v) for v in self.log_a):
            raise ValueError(f"SNCurve {self.name!r}: log_a must be finite")
        if any(a <= b for a, b in zip(self.knees_MPa, self.knees_MPa[1:])):
            raise ValueError(f"SNCurve {self.name!r}: knees_MPa must be strictly descending")
        if self.low_stress not in ("miner", "cutoff", "haibach"):
            raise ValueError(f"low_stress must be 'miner', 'cutoff' or 'haibach', got {self.low_stress!r}")
        if self.low_stress != "miner":
            e = self.endurance_MPa
            if e is None or not (np.isfinite(e) and e > 0):
                raise ValueError(f"low_stress={self.low_stress!r} needs a positive endurance_MPa")
            if self.knees_MPa and e >= self.knees_MPa[-1]:
                raise ValueError("endurance_MPa must lie below the lowest knee")
        for name in ("scf", "derating", "dff"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"SNCurve.{name} must be finite and positive, got {v!r}")
        if self.mean_correction not in ("none", "goodman", "gerber", "walker", "swt"):
            raise ValueError(f"unknown mean_correction {self.mean_correction!r}")
        if self.mean_correction in ("goodman", "gerber"):
            if self.ultimate_Pa is None or not (np.isfinite(self.ultimate_Pa) and self.ultimate_Pa > 0):
                raise ValueError(f"mean_correction={self.mean_correction!r} needs ultimate_Pa > 0")
        if not (0.0 <= self.walker_gamma <= 1.0):
            raise ValueError(f"walker_gamma must be in [0, 1], got {self.walker_gamma!r}")

    # ---------------------------------------------------------------- constructors
    @classmethod
    def basquin(cls, m: float, log_a: float, name: str = "basquin", **options) -> "SNCurve":
        """Single slope N = 10**log_a * S**-m (S stress range in MPa)."""
        return cls(name=name, m=(m,), log_a=(log_a,), **options)

    @classmethod
    def multi_slope(cls, m: tuple[float, ...], log_a: tuple[float, ...], name: str = "multi-slope",
                    **options) -> "SNCurve":
        """Segments (m_i, log a_i), high stress first; knees where consecutive lines cross."""
        m = tuple(float(v) for v in m)
        log_a = tuple(float(v) for v in log_a)
        if len(m) != len(log_a):
            raise ValueError("m and log_a must have the same length")
        if any(m1 == m2 for m1, m2 in zip(m, m[1:])):
            raise ValueError("consecutive segments must have different slopes")
        knees = tuple(10.0 ** ((a1 - a2) / (m1 - m2)) for m1, m2, a1, a2 in zip(m, m[1:], log_a, log_a[1:]))
        return cls(name=name, m=m, log_a=log_a, knees_MPa=knees, **options)

    @classmethod
    def tabulated(cls, stress_MPa, cycles, name: str = "tabulated", low_stress: LowStress = "cutoff",
                  **options) -> "SNCurve":
        """Log-log interpolation through (stress range [MPa], cycles) points.

        The first segment extends above the highest stress; below the lowest stress
        ``low_stress`` applies with ``endurance_MPa`` = the lowest table stress.
        """
        s = np.asarray(stress_MPa, dtype=np.float64)
        n = np.asarray(cycles, dtype=np.float64)
        if s.ndim != 1 or s.shape != n.shape or s.size < 2:
            raise ValueError("tabulated curve needs two equal-length 1-D arrays of >= 2 points")
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(n)) and np.all(s > 0) and np.all(n > 0)):
            raise ValueError("tabulated stresses and cycles must be finite and positive")
        order = np.argsort(-s)
        s, n = s[order], n[order]
        if np.any(np.diff(s) >= 0) or np.any(np.diff(n) <= 0):
            raise ValueError("tabulated cycles must increase strictly as stress decreases")
        ls, ln = np.log10(s), np.log10(n)
        m = -(ln[1:] - ln[:-1]) / (ls[1:] - ls[:-1])
        log_a = ln[:-1] + m * ls[:-1]
        return cls(name=name, m=tuple(m), log_a=tuple(log_a), knees_MPa=tuple(s[1:-1]),
                   low_stress=low_stress, endurance_MPa=float(s[-1]), **options)

    @classmethod
    def vaps_copper(cls, low_stress: LowStress = "haibach", **options) -> "SNCurve":
        """Seed 004 section 8: Marks (1958) annealed copper endurance x 0.42 (Faires).

        31.6 ... 54.6 MPa at 1e7 ... 1e4 cycles. Below 31.6 MPa the default is Haibach
        (m' = 2m - 1): copper has no true endurance limit and a monitor should not
        drop the many cycles just below the table. ``low_stress="cutoff"`` reproduces
        the report's endurance-limit reading.
        """
        stress = tuple(_FAIRES_COMBINED * s for s in _MARKS_COPPER_MPA)
        return cls.tabulated(stress, _MARKS_COPPER_CYCLES, name="VAPS copper (Marks x 0.42)",
                             low_stress=low_stress, **options)

    @classmethod
    def vaps_lab_calibrated(cls, low_stress: LowStress = "haibach", **options) -> "SNCurve":
        """``vaps_copper`` shifted in life to seed 004's lab failures (App. 2), x 3.74 in life.

        Fitted by ``models.fatigue.lab_calibration.vaps_lab_calibration`` (method, mean-stress convention
        and uncertainty documented there): the test-calibrated alternative to the
        handbook-conservative ``vaps_copper``.
        """
        from models.fatigue.lab_calibration import vaps_lab_calibration  # it builds on this module

        return vaps_lab_calibration(cls.vaps_copper(low_stress=low_stress)).curve(**options)

    @classmethod
    def dnv_rp_c203(cls, detail: str, environment: Literal["air", "seawater_cp"] = "air",
                    knee: Literal["intersection", "cycles"] = "intersection",
                    **options) -> "SNCurve":
        """DNV-RP-C203 Edition April 2016 curve ``detail`` (B1 ... W3).

        ``environment="air"``: Table 2-1; ``"seawater_cp"``: Table 2-2 (seawater with
        cathodic protection). Bilinear, m2 = 5 continues below the knee (no cut-off, as
        the RP prescribes for variable amplitude). Thickness effects are left to ``scf``.

        ``knee``: ``"intersection"`` (default, the RP's tables as printed) uses the printed
        log a2, so the knee is where the two lines cross (its N is 1e7 / 1e6 to the printed
        digits); ``"cycles"`` forces the knee to exactly N = 1e7 (air) / 1e6 (seawater_cp)
        and recomputes log a2 = log N_knee + m2 log S_knee with S_knee from the first
        segment, as qats and fatpack do (lives below the knee differ by about 0.15 %).
        """
        if detail not in _DNV_2016_AIR:
            raise ValueError(f"unknown DNV-RP-C203 (2016) detail {detail!r}; one of {sorted(_DNV_2016_AIR)}")
        m1, log_a1, m2, log_a2 = _DNV_2016_AIR[detail]
        if environment == "seawater_cp":
            log_a1 = _DNV_2016_SEAWATER_CP_LOG_A1[detail]
        elif environment != "air":
            raise ValueError(f"environment must be 'air' or 'seawater_cp', got {environment!r}")
        if knee == "cycles":
            log_n_knee = 7.0 if environment == "air" else 6.0
            log_a2 = log_n_knee + m2 * (log_a1 - log_n_knee) / m1
        elif knee != "intersection":
            raise ValueError(f"knee must be 'intersection' or 'cycles', got {knee!r}")
        return cls.multi_slope((m1, m2), (log_a1, log_a2), name=f"DNV-RP-C203:2016 {detail} {environment}",
                               **options)

    @classmethod
    def dnv_chain_studless(cls, **options) -> "SNCurve":
        """DNV-OS-E301 studless chain T-N curve: N = 6.0e10 * S**-3, S in MPa on the nominal area."""
        return cls.basquin(3.0, float(np.log10(6.0e10)), name="DNV-OS-E301 studless chain", **options)

    # -------------------------------------------------------------------- evaluation
    @property
    def _endurance(self) -> float:
        """``endurance_MPa``, which ``__post_init__`` requires for a cut-off or Haibach tail."""
        if self.endurance_MPa is None:
            raise ValueError(f"SNCurve {self.name!r} has no endurance_MPa")
        return float(self.endurance_MPa)

    @cached_property
    def _segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(m, log_a, ascending lower bounds in MPa) including a Haibach tail."""
        m, log_a, knees = list(self.m), list(self.log_a), list(self.knees_MPa)
        if self.low_stress == "haibach":
            e = self._endurance
            m_tail = 2.0 * m[-1] - 1.0
            log_n_e = log_a[-1] - m[-1] * np.log10(e)
            m.append(m_tail)
            log_a.append(log_n_e + m_tail * np.log10(e))
            knees.append(e)
        return np.asarray(m), np.asarray(log_a), np.asarray(knees[::-1])

    @cached_property
    def kernel_params(self) -> np.ndarray:
        """The curve as the compiled loops read it (``models.fatigue._loops``): [scale from
        nominal Pa ranges to the curve's MPa (scf x derating / 1e6), cut-off MPa (0 if
        none), n_seg, m_i..., ln(dff / a_i)..., ascending segment bounds MPa...]."""
        m, log_a, bounds = self._segments
        cutoff = self._endurance if self.low_stress == "cutoff" else 0.0
        with np.errstate(divide="ignore"):
            return np.concatenate(([self.scf * self.derating / _MPA, cutoff, m.size], m,
                                   np.log(self.dff * 10.0 ** -log_a), bounds))

    @cached_property
    def _mpa_params(self) -> np.ndarray:
        """``kernel_params`` for ranges already in the curve's MPa (scale 1: exact)."""
        params = self.kernel_params.copy()
        params[0] = 1.0
        return params

    def effective_range_MPa(self, range_Pa, mean_Pa=None) -> np.ndarray:
        """Stress range in MPa entering the curve: mean-corrected, times scf and derating."""
        r = np.asarray(range_Pa, dtype=np.float64)
        if not np.all(r >= 0) or not np.all(np.isfinite(r)):
            raise ValueError("stress ranges must be finite and >= 0")
        if self.mean_correction == "none":
            return r * self.kernel_params[0]  # one product, as the compiled loops scale
        if mean_Pa is None:
            raise ValueError(f"mean_correction={self.mean_correction!r} needs mean stresses")
        sm = np.asarray(mean_Pa, dtype=np.float64) * self.scf
        s = _mean_corrected(r * self.scf, sm, self.mean_correction, self.ultimate_Pa, self.walker_gamma)
        return s * (self.derating / _MPA)

    def damage_per_cycle(self, range_Pa, mean_Pa=None, counts=1.0) -> np.ndarray:
        """Miner damage count / N(S) (times ``dff``) of each cycle; stress ranges in Pa.

        Evaluated by the compiled loops' own per-cycle function (``_loops.damage_loop``,
        exp(m ln S + ln(dff / a)) with their log and exp), so a cycle's damage has the same
        bits here as in the committed Miner sum."""
        if self.mean_correction == "none":  # the check, the scaling and the loop in one call
            r = np.asarray(range_Pa, dtype=np.float64)
            n = np.asarray(counts, dtype=np.float64)
            if n.shape == r.shape or n.ndim == 0:
                n = n if n.shape == r.shape else np.full(r.shape, float(n))
                scaled = _loops.scaled_damage_compiled or _loops.scaled_damage_loop
                ok, d = scaled(np.ascontiguousarray(r).reshape(-1),
                               np.ascontiguousarray(n).reshape(-1), self.kernel_params[0],
                               self._mpa_params)
                if not ok:
                    raise ValueError("stress ranges must be finite and >= 0")
                return d.reshape(r.shape)[()]
        s = self.effective_range_MPa(range_Pa, mean_Pa)
        n = np.asarray(counts, dtype=np.float64)
        if n.shape != s.shape:
            s, n = np.broadcast_arrays(s, n)
        # looked up per call: the compiled loop is loaded (numba imported) only when used
        loop = _loops.damage_compiled or _loops.damage_loop
        d = loop(np.ascontiguousarray(s).reshape(-1), np.ascontiguousarray(n).reshape(-1),
                 self._mpa_params)
        return d.reshape(s.shape)[()]

    def cycles_to_failure(self, range_Pa, mean_Pa=None) -> np.ndarray:
        """N(S) for stress ranges in Pa (inf below a cut-off or for zero range); excludes dff."""
        d = self.damage_per_cycle(range_Pa, mean_Pa) / self.dff
        with np.errstate(divide="ignore"):
            return 1.0 / d

    def stress_range_at(self, cycles) -> np.ndarray:
        """Nominal zero-mean stress range [Pa] with ``cycles`` to failure (the inverse of N).

        Includes scf and derating (not dff). Below a cut-off the endurance stress is returned.
        """
        n = np.asarray(cycles, dtype=np.float64)
        if not np.all(np.isfinite(n)) or np.any(n <= 0):
            raise ValueError("cycles must be finite and positive")
        m, log_a, bounds = self._segments
        bounds_desc = bounds[::-1]
        # cycles at the knees, ascending (segment i covers N up to knee i)
        n_knees = 10.0 ** (log_a[: bounds.size] - m[: bounds.size] * np.log10(bounds_desc))
        seg = np.searchsorted(n_knees, n, side="left")
        s = 10.0 ** ((log_a[seg] - np.log10(n)) / m[seg])
        if self.low_stress == "cutoff":
            s = np.maximum(s, self._endurance)
        return s * _MPA / (self.scf * self.derating)

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict:
        """JSON-serialisable description (floats round-trip exactly through JSON)."""
        d = asdict(self)
        for key in ("m", "log_a", "knees_MPa"):
            d[key] = list(d[key])
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SNCurve":
        return cls(**{**d, "m": tuple(d["m"]), "log_a": tuple(d["log_a"]), "knees_MPa": tuple(d["knees_MPa"])})

    def with_factors(self, **changes) -> "SNCurve":
        """A copy with factors or options replaced (``scf``, ``derating``, ``dff``, ...)."""
        return replace(self, **changes)




def _mean_corrected(s: np.ndarray, sm: np.ndarray, kind: str, su: float | None, gamma: float) -> np.ndarray:
    """Equivalent fully reversed stress range for range s and mean sm (Pa)."""
    if not np.all(np.isfinite(sm)):
        raise ValueError("mean stresses must be finite")
    if kind in ("goodman", "gerber"):
        ratio = np.maximum(sm, 0.0) / su
        denom = 1.0 - (ratio if kind == "goodman" else ratio * ratio)
        with np.errstate(divide="ignore"):
            return np.where(denom > 0.0, s / np.where(denom > 0.0, denom, 1.0), np.inf)
    g = 0.5 if kind == "swt" else gamma
    s_max = sm + 0.5 * s
    amp = 0.5 * s
    return np.where(s_max > 0.0, 2.0 * np.power(np.maximum(s_max, 0.0), 1.0 - g) * np.power(amp, g), 0.0)
