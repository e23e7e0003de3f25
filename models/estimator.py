"""Buoy motion -> top tension estimator (no load cell, or a cross-check of one).

Estimated tension = quasi-static catenary tension at the instantaneous fairlead position
                  + axial dynamic increment (seed 002)
                  + elastic-drag "jerk" increment (seed 001, B3).

* Quasi-static: any vectorised ``quasi_static(x_offset_m, z_heave_m) -> (T, H, V, flags)``
  (N, N, N, uint8 :class:`Flag` bits). ``x_offset_m`` is the horizontal anchor -> fairlead
  distance minus the nominal span (sway included: the line turns with the buoy), ``z_heave_m``
  the fairlead rise. :class:`LinearisedQuasiStatic` (from a 2x2 end stiffness) and
  :class:`QuasiStaticGrid` (a bilinear table built once from any slow solver, e.g. the
  catenary) are provided.
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
SETTLING (IMU integrator warming up, or the first two samples of a stream).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Callable

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from models.dynamics import ElasticDragCord, axial_impedance, finite_line_added_mass, jerk_step
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
    the mean position), T = hypot(H, V). H <= 0 or T <= 0 is flagged SLACK (and clipped);
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


@numba.njit(cache=True)
def _bilinear(x, z, x0, dx, z0, dz, hs, vs, fs, out_t, out_h, out_v, out_f, range_bit):
    nx, nz = hs.shape
    for k in range(x.size):
        fx = (x[k] - x0) / dx
        fz = (z[k] - z0) / dz
        flag = 0
        if fx < 0.0 or fx > nx - 1.0 or fz < 0.0 or fz > nz - 1.0:
            flag = range_bit
        fx = min(max(fx, 0.0), nx - 1.0)
        fz = min(max(fz, 0.0), nz - 1.0)
        i = min(int(fx), nx - 2)
        j = min(int(fz), nz - 2)
        u = fx - i
        w = fz - j
        a, b, c, d = (1 - u) * (1 - w), u * (1 - w), (1 - u) * w, u * w
        h = a * hs[i, j] + b * hs[i + 1, j] + c * hs[i, j + 1] + d * hs[i + 1, j + 1]
        v = a * vs[i, j] + b * vs[i + 1, j] + c * vs[i, j + 1] + d * vs[i + 1, j + 1]
        out_h[k] = h
        out_v[k] = v
        out_t[k] = math.sqrt(h * h + v * v)
        out_f[k] = flag | fs[i, j] | fs[i + 1, j] | fs[i, j + 1] | fs[i + 1, j + 1]


@dataclass(frozen=True)
class QuasiStaticGrid:
    """A quasi-static model tabulated on a regular (x_offset, z) grid, bilinear in between.

    Built once from any vectorised ``quasi_static`` (e.g. the catenary solver) so the
    estimator's per-sample cost is a few array operations. H and V are interpolated and
    T = hypot(H, V) (more accurate than interpolating T near slack). Flags are OR-ed over
    the four surrounding nodes; positions outside the grid are clamped to its edge and flagged
    OUT_OF_RANGE.
    """

    x: NDArray[np.float64]
    z: NDArray[np.float64]
    h: NDArray[np.float64]
    v: NDArray[np.float64]
    flags: NDArray[np.uint8]

    @classmethod
    def from_function(
        cls, quasi_static: QuasiStatic, x: ArrayLike, z: ArrayLike
    ) -> QuasiStaticGrid:
        xg = np.asarray(x, dtype=float)
        zg = np.asarray(z, dtype=float)
        for name, g in (("x", xg), ("z", zg)):
            if g.ndim != 1 or g.size < 2 or not np.all(np.isfinite(g)):
                raise ValueError(f"grid {name} must be a finite 1-D array of >= 2 points")
            if not np.allclose(np.diff(g), g[1] - g[0], rtol=1e-9, atol=0) or g[1] <= g[0]:
                raise ValueError(f"grid {name} must be increasing and evenly spaced")
        xx, zz = np.meshgrid(xg, zg, indexing="ij")
        _, h, v, f = quasi_static(xx.ravel(), zz.ravel())
        shape = xx.shape
        return cls(
            x=xg, z=zg,
            h=np.asarray(h, float).reshape(shape),
            v=np.asarray(v, float).reshape(shape),
            flags=np.asarray(f, np.uint8).reshape(shape),
        )

    def __call__(self, x: NDArray[np.float64], z: NDArray[np.float64]):
        x = np.ascontiguousarray(x, dtype=float)
        z = np.ascontiguousarray(z, dtype=float)
        n = x.size
        t, h, v, f = np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.uint8)
        _bilinear(x, z, self.x[0], self.x[1] - self.x[0], self.z[0], self.z[1] - self.z[0],
                  self.h, self.v, self.flags, t, h, v, f, np.uint8(Flag.OUT_OF_RANGE))
        return t, h, v, f


@dataclass(frozen=True)
class EstimatorConfig:
    """Static description of the mooring line for the dynamic increments (SI units).

    span: nominal horizontal anchor -> fairlead distance (m); height: fairlead above the
    anchor at zero heave (m); line_length (m); mass_per_length: in-air mass (kg/m) for axial
    inertia; ea: axial stiffness (N); axial_model: "finite" | "infinite" | "none"; drag: the
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
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"EstimatorConfig.{name} must be finite and > 0, got {v!r}")
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
    jerk_y: the jerk ODE state V|V| (m^2/s^2); imu: the IMU integrator memory, if used.
    """

    history: list[list[float]] | None = None
    jerk_y: float = 0.0
    samples_seen: int = 0
    imu: dict | None = field(default=None)

    def to_dict(self) -> dict:
        return {
            "history": self.history,
            "jerk_y": self.jerk_y,
            "samples_seen": self.samples_seen,
            "imu": self.imu,
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
        return cls(history=hist, jerk_y=y, samples_seen=seen, imu=d.get("imu"))


def _as_block(name: str, value: ArrayLike, n: int | None) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array")
    if n is not None and arr.size != n:
        raise ValueError(f"{name} has {arr.size} samples, expected {n}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


_AXIAL_MODES = {"none": 0, "finite": 1, "infinite": 2}


@numba.njit(cache=True)
def _dynamic_core(p, span, height, dt, t_qs, h, v, flags, axial_mode, axial_gain, drag_on,
                  drag_k, drag_b, y0, tan_flat, total, axial, drag, angle):
    """Per-sample dynamic increments (see the module docstring); returns the jerk state.

    p: (3, n + 2) surge, sway, heave with the two previous samples first.
    """
    inv_dt = 1.0 / dt
    y = y0
    xs = span + p[0, 1]
    chord_prev = math.sqrt(xs * xs + p[1, 1] ** 2 + (height + p[2, 1]) ** 2)
    for i in range(t_qs.size):
        j = i + 2
        xs = span + p[0, j]
        ys = p[1, j]
        hor = math.sqrt(xs * xs + ys * ys)
        tq, hi, vi = t_qs[i], h[i], v[i]
        f = flags[i]
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
        d_i = 0.0
        if drag_on:
            zc = height + p[2, j]
            chord = math.sqrt(hor * hor + zc * zc)
            y = jerk_step(y, (chord - chord_prev) * inv_dt, drag_b)
            chord_prev = chord
            d_i = drag_k * y
            if vi > tan_flat * hi:
                f |= 4  # Flag.FLAT_CORD
        tot = tq + a_i + d_i
        if tot <= 0.0:
            tot = 0.0
            f |= 1  # Flag.SLACK
        total[i] = tot
        axial[i] = a_i
        drag[i] = d_i
        angle[i] = math.atan2(vi, hi)
        flags[i] = f
    return y


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
        self._imu_saved = st.imu
        self._imu: DisplacementIntegrator | None = None
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

    @property
    def state(self) -> EstimatorState:
        """A snapshot of the stream state (history, jerk ODE, IMU filter memory)."""
        return EstimatorState(
            history=None if self._hist is None else self._hist.T.tolist(),
            jerk_y=self._jerk_y,
            samples_seen=self._seen,
            imu=self._imu.state() if self._imu is not None else self._imu_saved,
        )

    # ------------------------------------------------------------------ inputs
    def update(
        self,
        heave: ArrayLike,
        surge: ArrayLike,
        sway: ArrayLike,
        heading_deg: ArrayLike | None = None,
    ) -> Estimate:
        """Estimate tension for a block of displacements (m) in the motion frame.

        ``heading_deg`` (optional, scalar or per sample): angle of the input's x-axis from the
        mooring's mean direction, counter-clockwise; the horizontal inputs are rotated into
        the mooring frame first (for buoy-frame displacements).
        """
        z = _as_block("heave", heave, None)
        x = _as_block("surge", surge, z.size)
        y = _as_block("sway", sway, z.size)
        if heading_deg is not None:
            x, y = _rotate(x, y, heading_deg, z.size)
        return self._estimate(x, y, z, settling=None)

    def update_accel(
        self,
        accel_x: ArrayLike,
        accel_y: ArrayLike,
        accel_z: ArrayLike,
        heading_deg: ArrayLike | None = None,
    ) -> Estimate:
        """As :meth:`update` from IMU accelerations (m/s^2, gravity removed, motion frame),
        double-integrated without drift by :class:`models.imu.DisplacementIntegrator`.
        Samples before the integrator has settled are flagged SETTLING."""
        az = _as_block("accel_z", accel_z, None)
        a = np.empty((3, az.size))
        a[0] = _as_block("accel_x", accel_x, az.size)
        a[1] = _as_block("accel_y", accel_y, az.size)
        a[2] = az
        if self._imu is None:
            self._imu = DisplacementIntegrator(self.config.dt, self.config.imu_f_cut, channels=3)
            if self._imu_saved is not None:
                self._imu.load_state(self._imu_saved)
        start = self._imu.samples_seen
        d = self._imu.update(a)
        settle_n = int(self._imu.settle_time_s / self.config.dt)
        settling = (start + np.arange(az.size)) < settle_n
        x, y = d[0], d[1]
        if heading_deg is not None:
            x, y = _rotate(x, y, heading_deg, az.size)
        return self._estimate(x, y, d[2], settling)

    # ------------------------------------------------------------------ core
    def _estimate(self, x, y, z, settling) -> Estimate:
        c = self.config
        n = z.size
        if n == 0:
            e = np.empty(0)
            return Estimate(e, e, e, e, e, np.empty(0, np.uint8))
        p = np.empty((3, n + 2))
        p[0, 2:], p[1, 2:], p[2, 2:] = x, y, z
        fresh = self._hist is None
        p[:, :2] = p[:, 2:3] if fresh else self._hist  # a fresh stream starts at rest
        x_off = np.hypot(c.span + x, y) - c.span
        t_qs, h, v, qflags = self.quasi_static(x_off, z)
        flags = np.array(qflags, dtype=np.uint8)
        total, axial, drag, angle = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        self._jerk_y = _dynamic_core(
            p, c.span, c.height, c.dt,
            np.ascontiguousarray(t_qs, dtype=float), np.ascontiguousarray(h, dtype=float),
            np.ascontiguousarray(v, dtype=float), flags,
            self._axial_mode, self._axial_gain, c.drag is not None, self._drag_k, self._drag_b,
            self._jerk_y, self._tan_flat, total, axial, drag, angle,
        )
        if settling is not None:
            flags[settling] |= np.uint8(Flag.SETTLING)
        if fresh:
            flags[:2] |= np.uint8(Flag.SETTLING)
        self._hist = p[:, -2:].copy()
        self._seen += n
        return Estimate(total, np.asarray(t_qs, dtype=float), axial, drag, angle, flags)


def _rotate(x, y, heading_deg, n):
    hd = np.asarray(heading_deg, dtype=float)
    if not np.all(np.isfinite(hd)) or hd.ndim > 1 or (hd.ndim == 1 and hd.size != n):
        raise ValueError("heading_deg must be finite, a scalar or one value per sample")
    ch, sh = np.cos(np.radians(hd)), np.sin(np.radians(hd))
    return ch * x - sh * y, sh * x + ch * y


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
