"""Buoy motion -> top tension estimator (no load cell, or a cross-check of one).

Estimated tension = quasi-static catenary tension at the instantaneous fairlead position
                  + axial dynamic increment (seed 002)
                  + elastic-drag "jerk" increment (seed 001, B3).

* Quasi-static: any vectorised ``quasi_static(x_offset_m, z_heave_m) -> (T, H, V, flags)``
  (N, N, N, uint8 :class:`Flag` bits). ``x_offset_m`` is the horizontal anchor -> fairlead
  distance minus the nominal span (sway included: the line turns with the buoy), ``z_heave_m``
  the fairlead rise. Provided: :class:`CatenaryQuasiStatic` (the catenary's precomputed
  TensionTable, :func:`catenary_estimator`, :func:`seed004_estimator`) and
  :class:`LinearisedQuasiStatic` (from a 2x2 end stiffness, for small motions).
* Axial, along the cable tangent at the top (angle atan2(V, H)): ``"finite"`` = the
  short-line limit of EA k U cot(kL), i.e. (m L / 3) x tangential acceleration;
  ``"infinite"`` = impedance sqrt(EA m) x tangential speed (a long, non-reflecting line);
  ``"none"``.
* Jerk: the support separation speed V_z = d|anchor -> fairlead|/dt drives
  V + mu d(V|V|)/dt = V_z (implicit Euler, stable at any step) and dT = k V|V|
  (:class:`models.dynamics.ElasticDragCord`); an approaching fairlead unloads the line.

Velocities and accelerations are backward differences of the displacements, continued across
blocks through the saved state. Output flags (bitwise, per sample): SLACK (estimate <= 0,
clipped to 0), ANCHOR_LIFTED and OUT_OF_RANGE (from the quasi-static model or the configured
calibrated range), FLAT_CORD (the top angle exceeds the flat-cord limit of the jerk model),
SETTLING (IMU integrator warming up, or the first two samples of a stream or after a
:meth:`MotionTensionEstimator.restart`).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models._jit import float_bits, kernel
from models.catenary import VAPS_DEPTH, Line, TensionTable, solve, vaps_mooring
from models.dynamics import (
    ElasticDragCord,
    axial_impedance,
    drag_constant,
    finite_line_added_mass,
    form_parameter,
    jerk_step,
)
from models.imu import DisplacementIntegrator


class Flag(enum.IntFlag):
    """Validity bits of an estimate (uint8 per sample)."""

    SLACK = 1
    ANCHOR_LIFTED = 2
    FLAT_CORD = 4
    OUT_OF_RANGE = 8
    SETTLING = 16


QuasiStatic = Callable[
    [NDArray[np.float64], NDArray[np.float64]],
    tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.uint8]],
]


def _check_range(name: str, rng: tuple[float, float]) -> tuple[float, float]:
    lo, hi = rng
    if math.isnan(lo) or math.isnan(hi) or not lo < hi:
        raise ValueError(f"{name} must be (low, high) with low < high, got {rng!r}")
    return float(lo), float(hi)


def _range_flags(
    x: NDArray, z: NDArray, xr: tuple[float, float], zr: tuple[float, float]
) -> NDArray[np.uint8]:
    out = (x < xr[0]) | (x > xr[1]) | (z < zr[0]) | (z > zr[1])
    return out.astype(np.uint8) * np.uint8(Flag.OUT_OF_RANGE)


@dataclass(frozen=True)
class LinearisedQuasiStatic:
    """Small-motion quasi-static mooring: fairlead tension components linear in the offset.

    H = h0 + dH/dx x + dH/dz z, V = v0 + dV/dx x + dV/dz z (the catenary's end stiffness at
    the mean position), T = hypot(H, V). H <= 0 is flagged SLACK (H clipped to 0, V to >= 0);
    positions outside ``x_range`` / ``z_range`` are flagged OUT_OF_RANGE.
    """

    h0: float
    v0: float
    k_hx: float
    k_hz: float
    k_vx: float
    k_vz: float
    x_range: tuple[float, float] = (-math.inf, math.inf)
    z_range: tuple[float, float] = (-math.inf, math.inf)

    def __post_init__(self) -> None:
        for name in ("h0", "v0", "k_hx", "k_hz", "k_vx", "k_vz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"LinearisedQuasiStatic.{name} must be finite, got {v!r}")
        _check_range("x_range", self.x_range)
        _check_range("z_range", self.z_range)

    def __call__(self, x: NDArray[np.float64], z: NDArray[np.float64]):
        h = self.h0 + self.k_hx * x + self.k_hz * z
        v = self.v0 + self.k_vx * x + self.k_vz * z
        slack = h <= 0.0
        h = np.maximum(h, 0.0)
        v = np.where(slack, np.maximum(v, 0.0), v)
        flags = _range_flags(x, z, self.x_range, self.z_range)
        flags |= slack.astype(np.uint8) * np.uint8(Flag.SLACK)
        return np.hypot(h, v), h, v, flags


class CatenaryQuasiStatic:
    """Quasi-static model from the catenary (models.catenary.TensionTable) of a mooring line
    around a nominal fairlead position ``span`` (m from the anchor), ``height`` (m above it).

    Positions outside the table are clamped to its edge and flagged OUT_OF_RANGE. SLACK: the
    horizontal tension vanishes (a slack column). ANCHOR_LIFTED: the line pulls the anchor
    up by more than ``anchor_uplift_limit_N`` (vertical equilibrium of the whole line:
    V_anchor = max(0, V_top - line weight), friction being horizontal).
    """

    def __init__(
        self,
        table: TensionTable,
        span: float,
        height: float,
        anchor_uplift_limit_N: float = 0.0,
    ):
        if not (table.x[0] <= span <= table.x[-1] and table.z[0] <= height <= table.z[-1]):
            raise ValueError(
                f"nominal fairlead (span {span!r}, height {height!r}) is outside the table"
            )
        if not anchor_uplift_limit_N >= 0:
            raise ValueError(f"anchor_uplift_limit_N must be >= 0, got {anchor_uplift_limit_N!r}")
        self.table = table
        self.span = float(span)
        self.height = float(height)
        self.anchor_uplift_limit_N = float(anchor_uplift_limit_N)
        self._line_weight = table.line.weight
        self._box = (table.x[0], table.x[-1], table.z[0], table.z[-1])

    def __call__(self, x_offset: NDArray[np.float64], z_heave: NDArray[np.float64]):
        xs = self.span + np.asarray(x_offset, dtype=float)
        zs = self.height + np.asarray(z_heave, dtype=float)
        if xs.shape != zs.shape:
            xs, zs = np.broadcast_arrays(xs, zs)
        shape = xs.shape
        xs, zs = xs.ravel(), zs.ravel()  # (a 1-D contiguous array itself, as the estimator's)
        xc, zc, flags = np.empty(xs.shape), np.empty(xs.shape), np.empty(xs.shape, np.uint8)
        _clamp_into(xs, zs, *self._box, xc, zc, flags)
        f = self.table.forces(xc, zc)
        _force_flags(f.h, f.v, self._line_weight, self.anchor_uplift_limit_N, flags)
        return (f.t.reshape(shape), f.h.reshape(shape), f.v.reshape(shape),
                flags.reshape(shape))


@kernel()
def _clamp_into(xs, zs, x0, x1, z0, z1, xc, zc, flags):
    """xc, zc: the points clamped into the box [x0, x1] x [z0, z1] as ``np.clip`` does (its
    comparisons: NaN stays NaN); flags: OUT_OF_RANGE where a point moved, else 0."""
    for i in range(xs.size):
        x, z = xs[i], zs[i]
        cx = x if x != x or x > x0 else x0
        cx = cx if cx != cx or cx < x1 else x1
        cz = z if z != z or z > z0 else z0
        cz = cz if cz != cz or cz < z1 else z1
        xc[i], zc[i] = cx, cz
        flags[i] = 8 if cx != x or cz != z else 0  # Flag.OUT_OF_RANGE


@kernel()
def _force_flags(h, v, line_weight, uplift_limit, flags):
    """Adds SLACK (no horizontal tension) and ANCHOR_LIFTED (the line pulls the anchor up by
    more than ``uplift_limit``) to ``flags`` from the fairlead forces ``h, v``."""
    for i in range(h.size):
        if h[i] <= 0.0:
            flags[i] |= 1  # Flag.SLACK
        if v[i] - line_weight > uplift_limit:
            flags[i] |= 2  # Flag.ANCHOR_LIFTED


@dataclass(frozen=True)
class EstimatorConfig:
    """Static description of the mooring line for the dynamic increments (SI units).

    span: nominal horizontal anchor -> fairlead distance (m); height: fairlead above the
    anchor at zero heave (m); line_length (m); mass_per_length: in-air mass (kg/m) for axial
    inertia; ea: axial stiffness (N, inf = inextensible); axial_model: "finite" | "infinite" | "none"; drag: the
    jerk model (None: off); flat_cord_max_deg: top angle above which FLAT_CORD is flagged when
    the jerk model is on; imu_f_cut: high-pass corner (Hz) of the IMU integrator.
    """

    dt: float
    span: float
    height: float
    line_length: float
    mass_per_length: float
    ea: float
    axial_model: str = "finite"
    drag: ElasticDragCord | None = None
    flat_cord_max_deg: float = 45.0
    imu_f_cut: float = 0.03

    def __post_init__(self) -> None:
        for name in ("dt", "span", "height", "line_length", "mass_per_length", "ea"):
            v = getattr(self, name)
            finite = math.isfinite(v) if name != "ea" else not math.isnan(v)
            if not (isinstance(v, (int, float)) and finite and v > 0):
                raise ValueError(f"EstimatorConfig.{name} must be finite and > 0, got {v!r}")
        if self.axial_model == "infinite" and math.isinf(self.ea):
            raise ValueError("EstimatorConfig.axial_model 'infinite' needs a finite ea")
        if self.axial_model not in ("finite", "infinite", "none"):
            raise ValueError(
                "EstimatorConfig.axial_model must be finite|infinite|none, "
                f"got {self.axial_model!r}"
            )
        if not 0 < self.flat_cord_max_deg <= 90:
            raise ValueError(
                "EstimatorConfig.flat_cord_max_deg must be in (0, 90], "
                f"got {self.flat_cord_max_deg!r}"
            )


@dataclass(frozen=True)
class Estimate:
    """Per-sample estimate (N) and its parts; ``flags`` are :class:`Flag` bits (uint8)."""

    tension: NDArray[np.float64]
    quasi_static: NDArray[np.float64]
    axial: NDArray[np.float64]
    drag: NDArray[np.float64]
    top_angle: NDArray[np.float64]
    flags: NDArray[np.uint8]


@dataclass
class EstimatorState:
    """Everything the estimator carries between blocks (JSON-ready via to_dict/from_dict).

    history: last two (surge, sway, heave) positions, oldest first, or None at stream start;
    jerk_y: the jerk ODE state V|V| (m^2/s^2); imu: the IMU integrator memory, if used;
    settling: how many of the next samples still settle (a fresh stream's first two, however
    the stream is split into blocks).
    """

    history: list[list[float]] | None = None
    jerk_y: float = 0.0
    samples_seen: int = 0
    imu: dict | None = field(default=None)
    settling: int = 0

    def to_dict(self) -> dict:
        return {
            "history": self.history,
            "jerk_y": self.jerk_y,
            "samples_seen": self.samples_seen,
            "imu": self.imu,
            "settling": self.settling,
        }

    @classmethod
    def from_dict(cls, d: dict) -> EstimatorState:
        hist = d.get("history")
        if hist is not None:
            arr = np.asarray(hist, dtype=float)
            if arr.shape != (2, 3) or not np.all(np.isfinite(arr)):
                raise ValueError(
                    "estimator state history must be 2 finite (surge, sway, heave) rows"
                )
            hist = arr.tolist()
        y = float(d.get("jerk_y", 0.0))
        if not math.isfinite(y):
            raise ValueError(f"estimator state jerk_y must be finite, got {y!r}")
        seen = int(d.get("samples_seen", 0))
        return cls(history=hist, jerk_y=y, samples_seen=seen, imu=d.get("imu"),
                   settling=int(d.get("settling", 0)))


def _as_block(name: str, value: ArrayLike, n: int | None,
              finite: bool = True) -> NDArray[np.float64]:
    """``value`` as a 1-D float array of ``n`` samples (any length for None), all finite
    unless ``finite`` is False (the caller checks)."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array")
    if n is not None and arr.size != n:
        raise ValueError(f"{name} has {arr.size} samples, expected {n}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


_AXIAL_MODES = {"none": 0, "finite": 1, "infinite": 2}


# no IMU integration in _advance: positions given (memory of the right shape, never used)
_NO_ACCEL, _NO_SOS, _NO_ZI = np.empty(0), np.zeros((2, 6)), np.zeros((3, 2, 2))


_SIDE_BY_SIDE = 1024  # samples from which the jerk ODE runs in four stretches side by side
_KEEP = 1 << 17  # samples of a block whose working memory an estimator keeps for the next


@kernel(inline="always")
def _section(c, s, v, z0, z1):
    """:func:`models.imu.sos_step`'s arithmetic for section ``s`` (coefficients ``c``: b0, b1,
    b2, a1, a2 of each section in turn) with its memory ``z0, z1``: (output, z0, z1)."""
    b0, b1, b2, a1, a2 = c[5 * s], c[5 * s + 1], c[5 * s + 2], c[5 * s + 3], c[5 * s + 4]
    y = b0 * v + z0
    return y, b1 * v - a1 * y + z1, b2 * v - a2 * y


@kernel(inline="always")
def _integrate(c, m, ax, ay, az, i, p):
    """Sample ``i`` of the accelerations through both sections of each channel into
    p[:, i + 2]; ``m``: the memory (channel x, y, z; section 0, 1; z0, z1), returned
    updated (a tuple: it stays in registers)."""
    v, x0, x1 = _section(c, 0, ax[i], m[0], m[1])
    p[0, i + 2], x2, x3 = _section(c, 1, v, m[2], m[3])
    v, y0, y1 = _section(c, 0, ay[i], m[4], m[5])
    p[1, i + 2], y2, y3 = _section(c, 1, v, m[6], m[7])
    v, z0, z1 = _section(c, 0, az[i], m[8], m[9])
    p[2, i + 2], z2, z3 = _section(c, 1, v, m[10], m[11])
    return (x0, x1, x2, x3, y0, y1, y2, y3, z0, z1, z2, z3)


@kernel(inline="always")
def _chords(p, a, b, span, height, out):
    """out[i - a] = |anchor -> fairlead| of the positions p[:, i + 2] for i in [a, b) (a
    branch-free loop: the square roots vectorise)."""
    for i in range(a, b):
        j = i + 2
        xs = span + p[0, j]
        ys = p[1, j]
        hor = math.sqrt(xs * xs + ys * ys)
        zc = height + p[2, j]
        out[i - a] = math.sqrt(hor * hor + zc * zc)


@kernel()
def _jerk_chain(vz, ys, b, y0):
    """The jerk ODE's states over the support speeds ``vz`` into ``ys`` from ``y0``
    (:func:`models.dynamics.jerk_step` one sample after the other); returns the last.

    Speed: each step waits for the one before (a square root and a division: their latency
    sets the pace, the core idles meanwhile), so a long block is cut in four stretches
    stepped side by side, the later three from a guess (rest); then each is redone from the
    true end of the one before until it meets its guessed run bit for bit (the ODE forgets
    its start within some ten steps: each step scales a difference by 2 s / (2 s + b),
    s = sqrt|y|), from where the guessed run is the true one (the same operations on the
    same values). Should they never meet, the redone run goes on to the stretch's end: the
    same bits always.
    """
    n = vz.size
    q = n // 4 if n >= _SIDE_BY_SIDE else 0  # the stretches' length (0: one after the other)
    y = y0
    if q == 0:
        for i in range(n):
            y = jerk_step(y, vz[i], b)
            ys[i] = y
        return y
    y1 = y2 = y3 = 0.0
    for k in range(q):
        y = jerk_step(y, vz[k], b)
        ys[k] = y
        y1 = jerk_step(y1, vz[q + k], b)
        ys[q + k] = y1
        y2 = jerk_step(y2, vz[2 * q + k], b)
        ys[2 * q + k] = y2
        y3 = jerk_step(y3, vz[3 * q + k], b)
        ys[3 * q + k] = y3
    for i in range(4 * q, n):
        y3 = jerk_step(y3, vz[i], b)
        ys[i] = y3
    for start, end, guessed_end in ((q, 2 * q, y1), (2 * q, 3 * q, y2), (3 * q, n, y3)):
        for i in range(start, end):
            y = jerk_step(y, vz[i], b)
            if float_bits(y) == float_bits(ys[i]):  # met: the guessed run from here on
                y = guessed_end
                break
            ys[i] = y
    return y


@kernel()
def _advance(p, fresh, ax, ay, az, sos, zi, span, height, dt, drag_on, drag_k, drag_b, y0,
             drag, vz):
    """The stream over a block: every sample's position (into ``p``) and drag increment
    (into ``drag``, n samples; :func:`_wanted` then estimates the wanted samples); ``vz``:
    n samples of working memory. Returns (ok, jerk state); ok False, nothing changed, if an
    acceleration is NaN or infinite.

    p: (3, n + 2) surge, sway, heave with the two previous samples first (set here for a
    ``fresh`` stream, which starts at rest). The positions are given in ``p``, or, when
    ``ax, ay, az`` hold the block's n IMU accelerations, integrated here sample by sample
    through the integrator's two second-order sections ``sos`` (its fourth-order high-pass)
    with memory ``zi`` (:func:`models.imu.sos_step`'s operations, the memory in registers).
    Then the chords |anchor -> fairlead| in one vectorised pass, their differences (the
    support speeds) and the jerk ODE over them (:func:`_jerk_chain`).
    """
    n = drag.size
    integrate = az.size == n
    if integrate:
        bad = False
        for i in range(n):  # x - x is 0 for finite x, NaN otherwise; the OR vectorises
            bad |= ((ax[i] - ax[i]) != 0.0) | ((ay[i] - ay[i]) != 0.0) | ((az[i] - az[i]) != 0.0)
        if bad:
            return False, y0
        # the sections' coefficients and memory in registers (stores into ``p`` could
        # alias them)
        c = (sos[0, 0], sos[0, 1], sos[0, 2], sos[0, 4], sos[0, 5],
             sos[1, 0], sos[1, 1], sos[1, 2], sos[1, 4], sos[1, 5])
        m = (zi[0, 0, 0], zi[0, 0, 1], zi[0, 1, 0], zi[0, 1, 1],
             zi[1, 0, 0], zi[1, 0, 1], zi[1, 1, 0], zi[1, 1, 1],
             zi[2, 0, 0], zi[2, 0, 1], zi[2, 1, 0], zi[2, 1, 1])
        for i in range(n):
            m = _integrate(c, m, ax, ay, az, i, p)
        k = 0
        for ch in range(3):
            for sec in range(2):
                zi[ch, sec, 0] = m[k]
                zi[ch, sec, 1] = m[k + 1]
                k += 2
    if fresh:
        for ch in range(3):
            p[ch, 0] = p[ch, 2]
            p[ch, 1] = p[ch, 2]
    if not drag_on:
        for i in range(n):
            drag[i] = 0.0
        return True, y0
    inv_dt = 1.0 / dt
    xs = span + p[0, 1]
    chord_prev = math.sqrt(xs * xs + p[1, 1] ** 2 + (height + p[2, 1]) ** 2)
    _chords(p, 0, n, span, height, drag)  # (the chords, for now)
    vz[0] = (drag[0] - chord_prev) * inv_dt
    for i in range(1, n):
        vz[i] = (drag[i] - drag[i - 1]) * inv_dt
    y = _jerk_chain(vz, drag, drag_b, y0)
    for i in range(n):
        drag[i] = drag_k * drag[i]
    return True, y


@kernel()
def _wanted(p, idx, t_qs, h, v, qflags, span, dt, axial_mode, axial_gain, drag_on, tan_flat,
            drag, total, qs, axial, angle, flags):
    """The estimates of the samples ``idx`` (see the module docstring), whose quasi-static
    ``t_qs, h, v, qflags`` are given in order, after :func:`_advance`: the k-th wanted
    sample's into ``total[k]``, ``qs[k]``, ``axial[k]``, ``angle[k]``, ``flags[k]``."""
    inv_dt = 1.0 / dt
    for k in range(idx.size):
        i = idx[k]
        j = i + 2
        xs = span + p[0, j]
        ys = p[1, j]
        hor = math.sqrt(xs * xs + ys * ys)
        tq, hi, vi = t_qs[k], h[k], v[k]
        f = qflags[k]
        a_i = 0.0
        if axial_mode != 0:
            if axial_mode == 1:  # short line: inertia of a third of the line, acceleration
                s0 = (p[0, j] - 2.0 * p[0, j - 1] + p[0, j - 2]) * inv_dt * inv_dt
                s1 = (p[1, j] - 2.0 * p[1, j - 1] + p[1, j - 2]) * inv_dt * inv_dt
                s2 = (p[2, j] - 2.0 * p[2, j - 1] + p[2, j - 2]) * inv_dt * inv_dt
            else:  # non-reflecting line: impedance, velocity
                s0 = (p[0, j] - p[0, j - 1]) * inv_dt
                s1 = (p[1, j] - p[1, j - 1]) * inv_dt
                s2 = (p[2, j] - p[2, j - 1]) * inv_dt
            if tq > 0.0 and hor > 0.0:
                a_i = axial_gain * ((hi / tq) * (xs * s0 + ys * s1) / hor + (vi / tq) * s2)
        if drag_on and vi > tan_flat * hi:
            f |= 4  # Flag.FLAT_CORD
        tot = tq + a_i + drag[i]
        if tot <= 0.0:
            tot = 0.0
            f |= 1  # Flag.SLACK
        total[k] = tot
        qs[k] = tq
        axial[k] = a_i
        angle[k] = math.atan2(vi, hi)
        flags[k] = f


class MotionTensionEstimator:
    """Streaming motion -> tension estimator; feed blocks, save and restore its state.

    >>> est = MotionTensionEstimator(config, quasi_static)
    >>> out = est.update(heave, surge, sway)          # displacements (m)
    >>> out = est.update_accel(ax, ay, az)            # or IMU accelerations (m/s^2)
    >>> saved = est.state.to_dict()                   # JSON-ready
    >>> est2 = MotionTensionEstimator(config, quasi_static, EstimatorState.from_dict(saved))
    """

    def __init__(
        self,
        config: EstimatorConfig,
        quasi_static: QuasiStatic,
        state: EstimatorState | None = None,
    ):
        self.config = config
        self.quasi_static = quasi_static
        st = state if state is not None else EstimatorState()
        self._hist = None if st.history is None else np.asarray(st.history, dtype=float).T.copy()
        self._jerk_y = float(st.jerk_y)
        self._seen = int(st.samples_seen)
        self._settling = int(st.settling)
        self._imu_saved = st.imu
        self._imu: DisplacementIntegrator | None = None
        self._scratch = np.empty(0)  # working memory kept between blocks (_buffers)
        c = config
        self._axial_mode = _AXIAL_MODES[c.axial_model]
        if c.axial_model == "finite":
            self._axial_gain = finite_line_added_mass(c.mass_per_length, c.line_length)
        elif c.axial_model == "infinite":
            self._axial_gain = axial_impedance(c.ea, c.mass_per_length)
        else:
            self._axial_gain = 0.0
        self._tan_flat = math.tan(math.radians(c.flat_cord_max_deg))
        if c.drag is None:
            self._drag_k, self._drag_b = 0.0, math.inf
        else:
            self._drag_k = c.drag.tension_coefficient
            self._drag_b = c.dt / c.drag.mu if c.drag.mu > 0 else math.inf

    def restart(self) -> None:
        """Forget the motion history and the jerk ODE: the next sample starts a fresh stream
        at rest (its first two estimates SETTLING). For a gap in the input, across which
        differences of positions are no velocities or accelerations."""
        self._hist = None
        self._jerk_y = 0.0

    @property
    def state(self) -> EstimatorState:
        """A snapshot of the stream state (history, jerk ODE, IMU filter memory)."""
        return EstimatorState(
            history=None if self._hist is None else self._hist.T.tolist(),
            jerk_y=self._jerk_y,
            samples_seen=self._seen,
            imu=self._imu.state() if self._imu is not None else self._imu_saved,
            settling=self._settling,
        )

    # ------------------------------------------------------------------ inputs
    def update(
        self,
        heave: ArrayLike,
        surge: ArrayLike,
        sway: ArrayLike,
        heading_deg: ArrayLike | None = None,
        want: NDArray[np.bool_] | None = None,
        compact: bool = False,
    ) -> Estimate:
        """Estimate tension for a block of displacements (m) in the motion frame.

        ``heading_deg`` (optional, scalar or per sample): angle of the input's x-axis from the
        mooring's mean direction, counter-clockwise; the horizontal inputs are rotated into
        the mooring frame first (for buoy-frame displacements).
        ``want`` (optional boolean mask, one per sample): the samples whose estimate is
        needed; the others come back as NaN. The stream state advances over every sample
        either way, so the wanted samples get exactly the values a full estimate gives (the
        quasi-static lookup, most of the cost, is skipped for the rest).
        ``compact``: the wanted samples' estimates only, in order (arrays of as many values
        as ``want`` holds True; their SETTLING flags as in the full estimate): for a caller
        wanting few samples of a long block, no per-sample arrays for the others.
        """
        z = _as_block("heave", heave, None)
        x = _as_block("surge", surge, z.size)
        y = _as_block("sway", sway, z.size)
        if heading_deg is not None:
            x, y = _rotate(x, y, heading_deg, z.size)
        return self._estimate(x, y, z, 0, _want_mask(want, z.size), compact)

    def update_accel(
        self,
        accel_x: ArrayLike,
        accel_y: ArrayLike,
        accel_z: ArrayLike,
        heading_deg: ArrayLike | None = None,
        want: NDArray[np.bool_] | None = None,
        compact: bool = False,
    ) -> Estimate:
        """As :meth:`update` from IMU accelerations (m/s^2, gravity removed, motion frame),
        double-integrated without drift by :class:`models.imu.DisplacementIntegrator`.
        Samples before the integrator has settled are flagged SETTLING."""
        az = _as_block("accel_z", accel_z, None, finite=False)
        a = (_as_block("accel_x", accel_x, az.size, finite=False),
             _as_block("accel_y", accel_y, az.size, finite=False), az)
        if self._imu is None:
            self._imu = DisplacementIntegrator(self.config.dt, self.config.imu_f_cut, channels=3)
            if self._imu_saved is not None:
                self._imu.load_state(self._imu_saved)
        settle_n = int(self._imu.settle_time_s / self.config.dt)
        settling = min(max(settle_n - self._imu.samples_seen, 0), az.size)
        want = _want_mask(want, az.size)
        try:
            if heading_deg is None:  # integrated in the estimator's loop
                return self._estimate(None, None, None, settling, want, compact, (a, self._imu))
            d = self._imu.update(np.stack(a))
        except ValueError:
            if all(np.all(np.isfinite(row)) for row in a):  # not the input's (the model's)
                raise
            for name, row in zip(("accel_x", "accel_y", "accel_z"), a):
                _as_block(name, row, az.size)  # names the field
            raise
        x, y = _rotate(d[0], d[1], heading_deg, az.size)
        return self._estimate(x, y, d[2], settling, want, compact)

    # ------------------------------------------------------------------ core
    def _buffers(self, n: int, drag_too: bool) -> tuple[NDArray[np.float64], ...]:
        """The block's positions (3, n + 2) and n samples of working memory in memory kept
        from block to block (for blocks of up to :data:`_KEEP` samples: a block's fresh
        pages cost more than the loop writing them, in page faults), and its drag increments
        (n): there too if ``drag_too``, else new (returned)."""
        size = 3 * (n + 2) + n + (n if drag_too else 0)
        if n > _KEEP:
            buf = np.empty(size)
        else:
            if self._scratch.shape[0] < size:
                self._scratch = np.empty(5 * n + 6)  # room for all three
            buf = self._scratch
        at = 3 * (n + 2)
        return (buf[:at].reshape(3, n + 2), buf[at:at + n],
                buf[at + n:size] if drag_too else np.empty(n))

    def _estimate(self, x, y, z, settling: int, want=None, compact: bool = False,
                  integrate: tuple[tuple[NDArray[np.float64], ...], DisplacementIntegrator]
                  | None = None) -> Estimate:
        """``settling``: how many of the first samples the IMU integrator still settles;
        ``integrate``: the IMU accelerations (x, y, z rows of n) to integrate here and the
        integrator (then x, y, z are None)."""
        c = self.config
        n = z.size if integrate is None else integrate[0][2].size
        if n == 0:
            e = np.empty(0)
            return Estimate(e, e, e, e, e, np.empty(0, np.uint8))
        idx = np.arange(n) if want is None else np.flatnonzero(want)
        m = idx.shape[0]
        # the drag of every sample is returned (so not in the kept memory, which the next
        # block overwrites) unless only some wanted samples' are (copied out by drag[idx])
        p, work, drag = self._buffers(n, compact and m < n)
        fresh = self._hist is None
        if not fresh:
            p[:, :2] = self._hist
        accel: tuple[NDArray[np.float64], ...]
        if integrate is None:
            p[0, 2:], p[1, 2:], p[2, 2:] = x, y, z
            accel, sos, zi = (_NO_ACCEL,) * 3, _NO_SOS, _NO_ZI
        else:
            accel, imu = integrate
            sos, zi = imu.loop_state()
            if sos.shape[0] != 2:  # _advance holds the two sections' memory in registers
                raise ValueError(f"the IMU integrator has {sos.shape[0]} sections, not 2")
        ok, jerk_y = _advance(p, fresh, *accel, sos, zi, c.span, c.height, c.dt,
                              c.drag is not None, self._drag_k, self._drag_b, self._jerk_y, drag,
                              work)
        if not ok:
            raise ValueError("acceleration contains NaN or infinite values")
        # the quasi-static lookup (most of the cost of an estimate) of the wanted samples
        x, y, z = p[0, 2:], p[1, 2:], p[2, 2:]
        if m < n:  # (every sample wanted: the rows themselves, no copies)
            x, y, z = x[idx], y[idx], z[idx]
        x_off = np.hypot(c.span + x, y) - c.span
        t_qs, h, v, qflags = self.quasi_static(x_off, z)
        total, qs, axial, angle = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
        flags = np.empty(m, np.uint8)
        _wanted(p, idx, np.ascontiguousarray(t_qs, dtype=float),
                np.ascontiguousarray(h, dtype=float), np.ascontiguousarray(v, dtype=float),
                np.ascontiguousarray(qflags, dtype=np.uint8), c.span, c.dt, self._axial_mode,
                self._axial_gain, c.drag is not None, self._tan_flat,
                drag, total, qs, axial, angle, flags)
        # the stream moves on only now (the quasi-static model may raise)
        if integrate is not None:
            integrate[1].advance(zi, n)
        self._jerk_y = jerk_y
        if fresh:
            self._settling = 2
        # SETTLING marks a block's first samples only (callers may rely on it)
        settling = max(settling, self._settling)
        self._settling = max(self._settling - n, 0)
        self._hist = p[:, -2:].copy()
        self._seen += n
        if m == n:
            flags[:settling] |= np.uint8(Flag.SETTLING)
            return Estimate(total, qs, axial, drag, angle, flags)
        if compact:
            if settling:  # (the usual block settles nothing: no search)
                flags[:int(np.searchsorted(idx, settling))] |= np.uint8(Flag.SETTLING)
            return Estimate(total, qs, axial, drag[idx], angle, flags)
        # every sample, the unwanted ones as not estimated (no axial increment, no flags)
        out = Estimate(np.full(n, np.nan), np.full(n, np.nan), np.zeros(n), drag,
                       np.full(n, np.nan), np.zeros(n, np.uint8))
        for full, part in ((out.tension, total), (out.quasi_static, qs), (out.axial, axial),
                           (out.top_angle, angle), (out.flags, flags)):
            full[idx] = part
        out.flags[:settling] |= np.uint8(Flag.SETTLING)
        return out


def _want_mask(want, n: int) -> NDArray[np.bool_] | None:
    if want is None:
        return None
    mask = np.asarray(want)
    if mask.dtype != np.bool_ or mask.shape != (n,):
        raise ValueError(f"want must be a boolean mask of {n} samples, got dtype {mask.dtype} "
                         f"and shape {mask.shape}")
    return mask


def _rotate(x, y, heading_deg, n):
    hd = np.asarray(heading_deg, dtype=float)
    if not np.all(np.isfinite(hd)) or hd.ndim > 1 or (hd.ndim == 1 and hd.size != n):
        raise ValueError("heading_deg must be finite, a scalar or one value per sample")
    ch, sh = np.cos(np.radians(hd)), np.sin(np.radians(hd))
    return ch * x - sh * y, sh * x + ch * y


def catenary_estimator(
    line: Line,
    span: float,
    height: float,
    dt: float,
    mass_per_length: float,
    drag_cd: float,
    drag_diameter: float,
    rho: float = 1025.0,
    x_range: tuple[float, float] = (-3.0, 3.5),
    z_range: tuple[float, float] = (-2.0, 2.0),
    table_rtol: float = 1e-3,
    anchor_uplift_limit_N: float = 0.0,
    axial_model: str = "finite",
    jerk: bool = True,
) -> tuple[EstimatorConfig, CatenaryQuasiStatic]:
    """Estimator configuration and quasi-static model for a catenary mooring ``line``.

    Builds the catenary TensionTable over the nominal fairlead position plus ``x_range`` /
    ``z_range`` (m) and the jerk model from the static shape there: span l = ``span``,
    alpha = sag / chord of the line's profile (:func:`models.dynamics.form_parameter`), EA =
    the series stiffness of the segments, L / sum(L_i / EA_i) (inextensible segments add no
    compliance; an all-inextensible line gives mu = 0, seed 001 eq 45). ``jerk=False`` leaves
    the jerk model out (required for a line that is nearly straight at the nominal position,
    alpha < 0.01, where the flat-cord drag theory has no meaning).
    """
    xr, zr = _check_range("x_range", x_range), _check_range("z_range", z_range)
    table = TensionTable(
        line, (span + xr[0], span + xr[1]), (max(height + zr[0], 0.0), height + zr[1]),
        rtol=table_rtol,
    )
    qs = CatenaryQuasiStatic(table, span, height, anchor_uplift_limit_N)
    prof = solve(line, float(span), float(height)).profile(200)
    alpha, _ = form_parameter(prof.x, prof.z)
    compliance = sum(seg.length / seg.ea for seg in line.segments)
    ea = line.length / compliance if compliance > 0 else math.inf
    cord = None
    if jerk:
        if alpha < 0.01:
            raise ValueError(
                f"the line is nearly straight at span {span!r} m (sag/chord {alpha:.4f}): "
                "the jerk model does not apply; pass jerk=False"
            )
        cord = ElasticDragCord(
            c=drag_constant(drag_cd, drag_diameter, rho), span=float(span),
            alpha=alpha, axial_stiffness=ea, length=line.length,
        )
    cfg = EstimatorConfig(
        dt=dt, span=float(span), height=float(height), line_length=line.length,
        mass_per_length=mass_per_length, ea=ea,
        axial_model=axial_model, drag=cord,
    )
    return cfg, qs


def seed004_estimator(
    dt: float = 0.05, span: float = 29.0, **options
) -> tuple[EstimatorConfig, CatenaryQuasiStatic]:
    """The VAPS mooring of seed 004 (models.catenary.vaps_mooring, 23 m) with a fairlead at
    ``span`` m from the anchor. ASSUMPTIONS (the report gives none of these): mean offset
    29 m (the 40 m line then holds ~220 N and goes taut ~3.5 m further out); drag on the
    bare 31 mm cable, C_D = 1.2, fresh water; in-air mass 1.10 kg/m (as the catenary
    module assumes); anchor uplift capacity 1000 N (the floated line lifts the anchor by
    ~575 N at rest, by design). ``options`` override :func:`catenary_estimator` arguments."""
    kw: dict[str, Any] = dict(mass_per_length=1.10, drag_cd=1.2, drag_diameter=0.031, rho=1000.0,
                              anchor_uplift_limit_N=1000.0)
    kw.update(options)
    return catenary_estimator(vaps_mooring(), span, VAPS_DEPTH, dt, **kw)


def simulate_tension(
    heave: ArrayLike,
    surge: ArrayLike,
    sway: ArrayLike,
    config: EstimatorConfig,
    quasi_static: QuasiStatic,
) -> Estimate:
    """Batch tension series for a whole motion record (e.g. :func:`models.waves.buoy_motion`),
    sampled at ``config.dt``: one call of a fresh estimator."""
    return MotionTensionEstimator(config, quasi_static).update(heave, surge, sway)
