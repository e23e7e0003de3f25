"""Quasi-static elastic catenary of a mooring line made of segments in series (anchor -> fairlead).

Physics (seed 001 eqs 1-3, seed 003's end forces, with axial stretch and Jonkman's Coulomb
seabed friction as in MoorPy): no drag, so the horizontal tension H is constant along the
suspended part and the vertical tension grows by the submerged weight of every element passed
(seed 002 eqs 21/49: top tension = bottom tension + weight x height for a homogeneous line).
On the seabed (flat, at the anchor's level) the grounded part carries a tension that friction
lowers by mu * w per metre from the touchdown point towards the anchor (never below zero).

Regimes (LineSolution.regime, names in REGIMES): fully suspended (including near-taut and
vertical lines: span 0 is solved as the limit span = 1e-9 L, H -> 0), grounded with and without
tension at the anchor, slack (H = 0: the heavy part piles on the seabed under a vertical column
that may fold over buoyant parts), and lying on the seabed. Limits: the seabed is flat at the
anchor's level and only the heavy part next to the anchor (no floats in it) may touch it; a
configuration that needs contact elsewhere (a mid-line sag or a float pressed down) is a clear
ValueError. An inextensible line that cannot reach the fairlead is a ValueError.

Conventions: x horizontal from the anchor towards the fairlead, z up from the anchor; weights
are SUBMERGED weights per unit length (N/m, negative = buoyant); tensions in N; stiffness
entries are derivatives of the fairlead force (H, V) with respect to fairlead motion (x, z).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from models.catenary import kernel as _k

REGIMES = {
    _k.SUSPENDED: "suspended",
    _k.GROUNDED: "grounded",
    _k.GROUNDED_SLACK_ANCHOR: "grounded, no anchor tension",
    _k.SLACK_PILED: "slack (vertical, rest piled on seabed)",
    _k.ON_SEABED: "on seabed",
}


def _number(value, name: str) -> float:
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be a number, got {value!r}") from err


@dataclass(frozen=True)
class Segment:
    """Homogeneous piece of line: unstretched length (m), submerged weight (N/m, negative =
    buoyant), axial stiffness EA (N, inf = inextensible)."""

    length: float
    weight: float
    ea: float = math.inf
    name: str = ""

    def __post_init__(self) -> None:
        for name in ("length", "weight", "ea"):
            object.__setattr__(self, name, _number(getattr(self, name), f"segment {name}"))
        if not (math.isfinite(self.length) and self.length > 0.0):
            raise ValueError(f"segment length must be finite and > 0, got {self.length!r}")
        if not math.isfinite(self.weight):
            raise ValueError(f"segment weight must be finite, got {self.weight!r}")
        if math.isnan(self.ea) or self.ea <= 0.0:
            raise ValueError(f"segment ea must be > 0 (inf = inextensible), got {self.ea!r}")


@dataclass(frozen=True)
class Joint:
    """Point element between two segments: submerged weight (N, negative = float) and dry
    mass (kg; not used by statics, carried for dynamics/added-mass models)."""

    weight: float = 0.0
    mass: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        for name in ("weight", "mass"):
            object.__setattr__(self, name, _number(getattr(self, name), f"joint {name}"))
        if not math.isfinite(self.weight):
            raise ValueError(f"joint weight must be finite, got {self.weight!r}")
        if not (math.isfinite(self.mass) and self.mass >= 0.0):
            raise ValueError(f"joint mass must be finite and >= 0, got {self.mass!r}")


@dataclass(frozen=True)
class Line:
    """Segments in series from the anchor (first) to the fairlead (last); `joints[i]` sits
    between segments i and i+1 (default: none, i.e. zero point loads). `seabed`: a flat seabed
    at the anchor's level with Coulomb friction coefficient `seabed_friction` on the grounded
    part; `seabed=False`: free line that may hang below the anchor (seed 003)."""

    segments: tuple[Segment, ...]
    joints: tuple[Joint, ...] = ()
    seabed: bool = True
    seabed_friction: float = 0.0
    _arrays: tuple = field(init=False, repr=False, compare=False)
    _length: float = field(init=False, repr=False, compare=False)
    _inextensible: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        segs = tuple(self.segments)
        if not segs or not all(isinstance(s, Segment) for s in segs):
            raise ValueError("segments must be a non-empty sequence of Segment")
        joints = tuple(self.joints) if self.joints else tuple(Joint() for _ in segs[1:])
        if len(joints) != len(segs) - 1 or not all(isinstance(j, Joint) for j in joints):
            raise ValueError(f"need {len(segs) - 1} Joint objects between {len(segs)} segments, "
                             f"got {len(joints)}")
        mu = _number(self.seabed_friction, "seabed_friction")
        if not (math.isfinite(mu) and mu >= 0.0):
            raise ValueError(f"seabed_friction must be finite and >= 0, got {mu!r}")
        object.__setattr__(self, "segments", segs)
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "seabed", bool(self.seabed))
        object.__setattr__(self, "seabed_friction", mu)
        arrays = (
            np.array([s.length for s in segs], dtype=float),
            np.array([s.weight for s in segs], dtype=float),
            np.array([1.0 / s.ea for s in segs], dtype=float),  # compliance, 0 = rigid
            np.array([j.weight for j in joints], dtype=float).reshape(len(segs) - 1),
        )
        for a in arrays:
            a.setflags(write=False)
        object.__setattr__(self, "_arrays", arrays)
        object.__setattr__(self, "_length", float(arrays[0].sum()))
        object.__setattr__(self, "_inextensible", not np.any(arrays[2] > 0.0))

    @classmethod
    def homogeneous(cls, length: float, weight: float, ea: float = math.inf,
                    seabed: bool = True, seabed_friction: float = 0.0) -> Line:
        return cls((Segment(length, weight, ea),), (), seabed, seabed_friction)

    @property
    def length(self) -> float:
        """Total unstretched length (m)."""
        return self._length

    @property
    def weight(self) -> float:
        """Total submerged weight including point loads (N)."""
        l, w, _, p = self._arrays
        return float(l @ w + p.sum())

    @property
    def inextensible(self) -> bool:
        return self._inextensible


@dataclass(frozen=True)
class Profile:
    """Line shape from anchor to fairlead: unstretched arc length s, x, z (m), tension (N)."""

    s: np.ndarray
    x: np.ndarray
    z: np.ndarray
    tension: np.ndarray


@dataclass(frozen=True)
class LineSolution:
    """Solved line; every field has the broadcast shape of (span, height), joint fields have
    one more trailing axis (one entry per joint, anchor side first).

    h: horizontal tension (N) along the suspended part (= at the fairlead);
    v_top: vertical tension at the fairlead (N, up = the line pulls the buoy down);
    h_anchor, v_anchor: tension components at the anchor (h_anchor < h with friction);
    grounded_length: unstretched length lying on the seabed (m);
    regime: codes of `REGIMES`;
    stiffness: (..., 2, 2) [[dH/dx, dH/dz], [dV/dx, dV/dz]] at the fairlead (N/m);
    joint_h, joint_v: tension components just above each joint (in the upper segment).
    """

    line: Line
    span: np.ndarray
    height: np.ndarray
    h: np.ndarray
    v_top: np.ndarray
    h_anchor: np.ndarray
    v_anchor: np.ndarray
    grounded_length: np.ndarray
    regime: np.ndarray
    stiffness: np.ndarray
    joint_h: np.ndarray
    joint_v: np.ndarray

    @property
    def t_top(self) -> np.ndarray:
        return np.hypot(self.h, self.v_top)

    @property
    def t_anchor(self) -> np.ndarray:
        return np.hypot(self.h_anchor, self.v_anchor)

    @property
    def top_angle(self) -> np.ndarray:
        """Angle of the line at the fairlead above the horizontal (rad)."""
        return np.arctan2(self.v_top, self.h)

    @property
    def anchor_angle(self) -> np.ndarray:
        """Angle of the line at the anchor above the horizontal (rad; < 0: leaves downwards)."""
        return np.arctan2(self.v_anchor, self.h_anchor)

    @property
    def joint_tension(self) -> np.ndarray:
        return np.hypot(self.joint_h, self.joint_v)

    def __getitem__(self, index) -> LineSolution:
        """Sub-solution for one element (or a slice) of the solved arrays."""
        pick = {name: getattr(self, name)[index] for name in
                ("span", "height", "h", "v_top", "h_anchor", "v_anchor", "grounded_length",
                 "regime", "stiffness", "joint_h", "joint_v")}
        return LineSolution(self.line, **pick)

    def profile(self, n: int = 50) -> Profile:
        """Shape and tension at n points evenly spaced in unstretched arc length (scalar
        solution only; index an array solution first)."""
        if np.ndim(self.h) != 0:
            raise ValueError("profile() needs a single solution: index the result first")
        if n < 2:
            raise ValueError(f"profile needs n >= 2 points, got {n}")
        return _profile(self, int(n))


def _as_float_array(value, name: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be numeric, got {value!r}") from err


def broadcast_pair(a, b, names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
    """Two inputs as float arrays of their common shape (real copies where broadcasting
    expands them, so the compiled kernels get ordinary contiguous arrays)."""
    x = _as_float_array(a, names[0])
    z = _as_float_array(b, names[1])
    try:
        shape = np.broadcast_shapes(x.shape, z.shape)
    except ValueError as err:
        raise ValueError(f"{names[0]} and {names[1]} do not broadcast together: {err}") from err
    x = np.require(x if x.shape == shape else np.broadcast_to(x, shape).copy(), requirements="C")
    z = np.require(z if z.shape == shape else np.broadcast_to(z, shape).copy(), requirements="C")
    return x, z


def _check_inputs(line: Line, span, height) -> tuple[np.ndarray, np.ndarray]:
    x, z = broadcast_pair(span, height, ("span", "height"))
    if not np.all(np.isfinite(x)):
        raise ValueError("span must be finite (got NaN or inf)")
    if not np.all(np.isfinite(z)):
        raise ValueError("height must be finite (got NaN or inf)")
    if np.any(x < 0.0):
        raise ValueError(f"span must be >= 0 (horizontal distance), got min {x.min()!r}")
    if line.seabed and np.any(z < 0.0):
        raise ValueError(f"height must be >= 0 with a seabed at the anchor (fairlead below the "
                         f"seabed), got min {z.min()!r}")
    if line._inextensible:
        chord = np.hypot(x, z)
        bad = chord >= line.length
        if np.any(bad):
            i = np.flatnonzero(bad.ravel())[0]
            raise ValueError(
                f"impossible geometry for an inextensible line: anchor-fairlead distance "
                f"{chord.ravel()[i]:.6g} m >= line length {line.length:.6g} m "
                f"(span={x.ravel()[i]!r}, height={z.ravel()[i]!r})")
    return x, z


_TOL = 1e-13


def _check_scalar(line: Line, x: float, z: float) -> None:
    if not math.isfinite(x):
        raise ValueError(f"span must be finite, got {x!r}")
    if not math.isfinite(z):
        raise ValueError(f"height must be finite, got {z!r}")
    if x < 0.0:
        raise ValueError(f"span must be >= 0 (horizontal distance), got {x!r}")
    if line.seabed and z < 0.0:
        raise ValueError(f"height must be >= 0 with a seabed at the anchor (fairlead below the "
                         f"seabed), got {z!r}")
    if line._inextensible and math.hypot(x, z) >= line._length:
        raise ValueError(
            f"impossible geometry for an inextensible line: anchor-fairlead distance "
            f"{math.hypot(x, z):.6g} m >= line length {line._length:.6g} m "
            f"(span={x!r}, height={z!r})")


def _solve_scalar(line: Line, x: float, z: float) -> LineSolution:
    _check_scalar(line, x, z)
    seg_l, seg_w, seg_c, joint_p = line._arrays
    nj = joint_p.shape[0]
    o = np.empty(11)
    jh = np.empty(nj)
    jv = np.empty(nj)
    _k.solve_one(x, z, seg_l, seg_w, seg_c, joint_p, line.seabed_friction, line.seabed, _TOL,
                 jh, jv, o)
    if o[6] != _k.OK:
        raise ValueError(_failure(line, o[6], x, z))
    f = np.float64
    scalars = (f(x), f(z), f(o[0]), f(o[1]), f(o[2]), f(o[3]), f(o[4]), np.int8(o[5]))
    # a scalar solve: numpy scalars stand for the fields' 0-d arrays
    return LineSolution(line, *scalars, o[7:11].reshape(2, 2), jh, jv)  # type: ignore[arg-type]


_SCALARS = (float, int, np.floating, np.integer)


def _failure(line: Line, status: float, x: float, z: float) -> str:
    if status == _k.OFF_SEABED_MODEL:
        return (f"span={x!r}, height={z!r}: the equilibrium needs seabed contact that is not "
                f"modelled (a buoyant part pressed onto the seabed, or a mid-line sag below it)")
    msg = f"no static equilibrium found for span={x!r}, height={z!r}"
    _, w, _, p = line._arrays
    if line.seabed and (np.any(w <= 0.0) or np.any(p < 0.0)):
        msg += ("; with floats or buoyant segments on a seabed the equilibrium may need seabed "
                "contact away from the anchor's heavy part, which is not modelled")
    return msg


def solve(line: Line, span, height) -> LineSolution:
    """Static equilibrium of `line` for fairlead(s) at horizontal distance `span` (m) and
    `height` (m) above the anchor; vectorised (arrays broadcast together)."""
    if isinstance(span, _SCALARS) and isinstance(height, _SCALARS):
        return _solve_scalar(line, float(span), float(height))
    x, z = _check_inputs(line, span, height)
    shape = x.shape
    xf = np.ascontiguousarray(x.ravel())
    zf = np.ascontiguousarray(z.ravel())
    seg_l, seg_w, seg_c, joint_p = line._arrays
    nj = joint_p.shape[0]
    out = np.empty((xf.size, 11))
    jh = np.empty((xf.size, nj))
    jv = np.empty((xf.size, nj))
    _k.solve_many(xf, zf, seg_l, seg_w, seg_c, joint_p, line.seabed_friction, line.seabed,
                  _TOL, out, jh, jv)
    failed = out[:, 6] != _k.OK
    if np.any(failed):
        i = int(np.flatnonzero(failed)[0])
        raise ValueError(_failure(line, out[i, 6], xf[i], zf[i]) +
                         f" ({int(failed.sum())} of {xf.size} positions failed)")
    o = out.reshape(shape + (11,))
    return LineSolution(
        line=line, span=x, height=z, h=o[..., 0], v_top=o[..., 1], h_anchor=o[..., 2],
        v_anchor=o[..., 3], grounded_length=o[..., 4], regime=o[..., 5].astype(np.int8),
        stiffness=o[..., 7:11].reshape(shape + (2, 2)),
        joint_h=jh.reshape(shape + (nj,)), joint_v=jv.reshape(shape + (nj,)))


def solve_line(span, height, length: float, weight: float, ea: float = math.inf,
               seabed: bool = True, seabed_friction: float = 0.0) -> LineSolution:
    """One homogeneous line from anchor to fairlead (see `solve`): unstretched `length` (m),
    submerged `weight` (N/m, negative = buoyant), axial stiffness `ea` (N, inf =
    inextensible), flat seabed at the anchor with Coulomb `seabed_friction`, or
    `seabed=False` for a free line that may dip below the anchor (seed 003)."""
    return solve(_homogeneous(_number(length, "length"), _number(weight, "weight"),
                              _number(ea, "ea"), bool(seabed),
                              _number(seabed_friction, "seabed_friction")), span, height)


@functools.lru_cache(maxsize=64)
def _homogeneous(length: float, weight: float, ea: float, seabed: bool, mu: float) -> Line:
    # immutable, so safe to share; saves rebuilding arrays on per-sample scalar calls
    return Line.homogeneous(length, weight, ea, seabed, mu)


def _profile(sol: LineSolution, n: int) -> Profile:
    line = sol.line
    seg_l, seg_w, seg_c, joint_p = line._arrays
    mu = line.seabed_friction
    h = float(sol.h)
    vf = float(sol.v_top)
    total = line.length
    s = np.linspace(0.0, total, n)
    starts = np.concatenate(([0.0], np.cumsum(seg_l)))
    # vertical tension at the bottom of each segment, from the top down
    vb = np.empty(seg_l.size)
    vt = vf
    for k in range(seg_l.size - 1, -1, -1):
        vb[k] = vt - seg_w[k] * seg_l[k]
        if k > 0:
            vt = vb[k] - joint_p[k - 1]
    gl = float(sol.grounded_length)
    regime = int(sol.regime)
    xs = np.empty(n)
    zs = np.empty(n)
    ts = np.empty(n)
    if regime in (_k.SLACK_PILED, _k.ON_SEABED) and h == 0.0:
        # slack along the seabed up to below the fairlead, then a vertical column
        span = float(sol.span)
        for i, si in enumerate(s):
            if si <= gl:
                xs[i], zs[i], ts[i] = min(si, span), 0.0, 0.0
                continue
            z, v = 0.0, 0.0
            for k in range(seg_l.size):
                lo, hi = max(starts[k], gl), min(starts[k + 1], si)
                if k > 0 and starts[k] > gl and starts[k] < si:
                    v += joint_p[k - 1]
                if hi > lo:
                    z += _k._rise(v, seg_w[k], hi - lo, seg_c[k])
                    v += seg_w[k] * (hi - lo)
            xs[i], zs[i], ts[i] = span, z, abs(v)
        return Profile(s, xs, zs, ts)
    # grounded tension profile: from the touchdown (tension h) down to the anchor
    def grounded_t(si: float) -> float:
        t = h
        pos = gl
        for k in range(seg_l.size - 1, -1, -1):
            lo, hi = starts[k], min(starts[k + 1], gl)
            if hi <= lo:
                continue
            if si >= hi:
                continue
            if hi < pos:  # crossed the joint at hi
                t = max(t - mu * joint_p[k], 0.0)
            seg_hi = hi
            end = max(si, lo)
            t = max(t - mu * seg_w[k] * (seg_hi - end), 0.0)
            pos = end
            if end == si:
                return t
        return t

    # stretched x of the grounded part by fine trapezoid integration of t/EA (exact for the
    # piecewise linear tension when breakpoints are included)
    def grounded_x(si: float) -> float:
        pts = np.union1d(np.linspace(0.0, si, 201), starts[(starts > 0) & (starts < si)])
        tt = np.array([grounded_t(p) for p in pts])
        cc = seg_c[np.clip(np.searchsorted(starts, pts, side="right") - 1, 0, seg_l.size - 1)]
        f = tt * cc
        return si + float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(pts)))

    x_td = grounded_x(gl) if gl > 0.0 else 0.0
    for i, si in enumerate(s):
        if gl > 0.0 and si <= gl:
            xs[i] = grounded_x(si)
            zs[i] = 0.0
            ts[i] = grounded_t(si)
            continue
        x0, z0 = x_td, 0.0
        k = int(min(np.searchsorted(starts, si, side="right") - 1, seg_l.size - 1))
        for j in range(k):
            lo = max(starts[j], gl)
            if starts[j + 1] <= lo:
                continue
            ell = starts[j + 1] - lo
            v_lo = vb[j] + seg_w[j] * (lo - starts[j])
            dx, dz = _piece_xz(h, v_lo + seg_w[j] * ell, seg_w[j], ell, seg_c[j])
            x0 += dx
            z0 += dz
        lo = max(starts[k], gl)
        r = si - lo
        v_lo = vb[k] + seg_w[k] * (lo - starts[k])
        v = v_lo + seg_w[k] * r
        dx, dz = _piece_xz(h, v, seg_w[k], r, seg_c[k]) if r > 0 else (0.0, 0.0)
        xs[i] = x0 + dx
        zs[i] = z0 + dz
        ts[i] = math.hypot(h, v)
    return Profile(s, xs, zs, ts)


def _piece_xz(h: float, vt: float, w: float, length: float, c: float) -> tuple[float, float]:
    if h == 0.0:
        raise ValueError("profile of a suspended piece needs H > 0")
    dx, dz, *_ = _k.piece(h, vt, w, length, c)
    return dx, dz
