"""Helical conductor stress in a centre-core electro-mechanical cable.

Seed 004 (VAPS mooring cable study, 1981), Appendix 4 and programs CABLE1/2/3, after
Knapp (1975). A wire-rope core carries the tension T (times ``core_load_share``); it
stretches by e_c = T / (A_c E_c) and twists by theta = G_c T P over one helix pitch P.
The conductor helix (radius R, circumference C = 2 pi R, lay angle a = atan(C / P)) is
deformed to pitch P' = P (1 + e_c) and circumference C' = 2 pi R' +/- R' theta, with
``+`` when the conductor lay has the same hand as the core twist (the VAPS failure
case: both left) and ``-`` when opposite. The strained lay angle is a' = atan(C' / P').

Axial (Knapp) stress, App. 4:      sigma_a = E_i | cos(a) / cos(a') (1 + e_c) - 1 |
Bending stress, App. 4:            sigma_b = E_i d/(2R) sin(a) [sin(a') - sin(a) cos(a) (1 + e_c) / cos(a')]
Shear stress from twist, App. 4:   tau = E_i / (2 (1 + nu)) | d sin(a) cos(a) / (2R) [cos(a')/cos(a) - cos(a)/cos(a') (1 + e_c)] |
Ductile combination, App. 4:       sigma = sqrt((sigma_a + sigma_b)^2 + 3 tau^2)

The primes in the bending and shear formulas are lost in the OCR; they are restored so
that both terms vanish in the unstrained cable. The seed states these terms are of order
1e-3 of the axial term for its cable and neglects them; so does the default here.

Since cos(a) / cos(a') = cos(a) sqrt(1 + tan^2 a'), the axial term is evaluated as
E_i | cos(a) sqrt((1 + e_c)^2 + (C' / P)^2) - 1 |, which needs no trigonometry per sample
(the hot path of the monitor evaluates it at every tension sample).

Twist boundary condition (issue 20; seed 004 section 2, App. 1; docs/CONDUCTOR.md)
----------------------------------------------------------------------------------
App. 1 measured the core with its end free to turn: e_c = T / (A_c E_c), twist per unit length
theta / P = G_c T. Reciprocity (Maxwell-Betti) makes the core's compliance symmetric, so a
torque M on the core adds G_c M to its strain and M / K_c to its twist per length, K_c [N m^2/rad]
being its torsional stiffness (not measured by the seed):

    e_c = T / (A_c E_c) + G_c M,        theta / P = G_c T + M / K_c.

- ``twist_restraint="free"`` (slip ring at the buoy, the seed's assumption): M = 0.
- ``"restrained"`` (both ends held, e.g. slip ring seized and anchor sunk, section 2): the
  torque balance theta = 0 gives M = -K_c G_c T and e_c = T (1 / (A_c E_c) - G_c^2 K_c): no
  twist, so the lay hand no longer matters, and the core is stiffer by 1 / (1 - G_c^2 K_c A_c E_c)
  (0.2 % per N m^2 of K_c for the VAPS core; K_c = 0, the default, neglects it).
- ``"limited"`` (the anchor bridle: +/-75 deg, section 2): the core twists freely until the
  total twist G_c T L over ``twist_length_m`` L reaches ``twist_limit_rad`` Phi; beyond,
  theta / P = Phi / L and M = (Phi / L - G_c T) K_c. Zero twist at zero tension is assumed.

Termination bending (``models.termination``) and yield (``HelixCable.conductor_yield_Pa``, the
copper's tensile yield, 68.9 MPa, seed 004 quoting the Materials Selector) are used outside
this module.

Public API
----------
- ``core_strain_twist(tension_N, cable) -> (e_c, theta / P)``: the core under the boundary
  condition above
- ``stress_terms(tension_N, cable, lay="left") -> (sigma_a, sigma_b, tau)`` [Pa]
- ``HelixCable`` (frozen dataclass), ``HelixCable.vaps_biw()``
- ``conductor_stress(tension_N, cable, lay="left", combined=False) -> ndarray``
  [Pa]; NaN/inf tension raises ValueError
- ``tension_for_stress(stress_Pa, cable, lay="left") -> ndarray`` [N], the inverse
  ("equivalent cable load" of the seed's predicted-failure table)
- ``cable_load(tension_N, stress_Pa, cable) -> ndarray`` [N], CABLE2/3's "cable load"
- ``sweep_helix_diameter(cable, tension_N, diameters_m) -> HelixSweep`` (CABLE2)
- ``sweep_pitch(cable, tension_N, pitches_m) -> HelixSweep`` (CABLE3)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np

from models.fatigue import _loops

Lay = Literal["left", "right"]
TwistRestraint = Literal["free", "restrained", "limited"]


@dataclass(frozen=True)
class HelixCable:
    """A centre-core cable: wire-rope core plus one helical conductor layer (SI units).

    ``core_twist_modulus`` is the core rotation per unit length per unit tension
    [rad / (N m)]; ``core_twist_hand`` is the hand in which tension twists the core.
    ``core_compressibility`` [m/N] shrinks the helix radius by c * T (seed 004 takes the
    core as incompressible, c = 0). ``twist_restraint``, ``twist_limit_rad`` (total twist
    allowed over ``twist_length_m`` when "limited") and ``core_torsional_stiffness_Nm2`` (K_c)
    set the twist boundary condition (module docstring). ``conductor_yield_Pa`` is the
    conductor's tensile yield (inf: not checked); the elastic model does not hold above it.
    """

    core_area_m2: float
    core_modulus_Pa: float
    core_twist_modulus: float
    pitch_m: float
    helix_radius_m: float
    conductor_modulus_Pa: float
    conductor_area_m2: float
    conductor_wire_diameter_m: float
    poisson_ratio: float
    core_twist_hand: Lay = "left"
    core_load_share: float = 1.0
    core_compressibility: float = 0.0
    twist_restraint: TwistRestraint = "free"
    twist_limit_rad: float = 0.0
    twist_length_m: float = 1.0
    core_torsional_stiffness_Nm2: float = 0.0
    conductor_yield_Pa: float = math.inf

    def __post_init__(self) -> None:
        positive = ("core_area_m2", "core_modulus_Pa", "pitch_m", "helix_radius_m",
                    "conductor_modulus_Pa", "conductor_area_m2", "conductor_wire_diameter_m")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(f"HelixCable.{name} must be a finite positive number, got {value!r}")
        if not (np.isfinite(self.core_twist_modulus) and self.core_twist_modulus >= 0):
            raise ValueError(f"HelixCable.core_twist_modulus must be >= 0, got {self.core_twist_modulus!r}")
        if not (0.0 < self.core_load_share <= 1.0):
            raise ValueError(f"HelixCable.core_load_share must be in (0, 1], got {self.core_load_share!r}")
        if not (np.isfinite(self.core_compressibility) and self.core_compressibility >= 0):
            raise ValueError(f"HelixCable.core_compressibility must be >= 0, got {self.core_compressibility!r}")
        if not (-1.0 < self.poisson_ratio < 0.5):
            raise ValueError(f"HelixCable.poisson_ratio must be in (-1, 0.5), got {self.poisson_ratio!r}")
        _check_lay(self.core_twist_hand, "core_twist_hand")
        if self.twist_restraint not in ("free", "restrained", "limited"):
            raise ValueError("HelixCable.twist_restraint must be 'free', 'restrained' or "
                             f"'limited', got {self.twist_restraint!r}")
        if not (np.isfinite(self.twist_limit_rad) and self.twist_limit_rad >= 0):
            raise ValueError(f"HelixCable.twist_limit_rad must be finite and >= 0, got {self.twist_limit_rad!r}")
        if not (np.isfinite(self.twist_length_m) and self.twist_length_m > 0):
            raise ValueError(f"HelixCable.twist_length_m must be finite and > 0, got {self.twist_length_m!r}")
        k_c = self.core_torsional_stiffness_Nm2
        if not (np.isfinite(k_c) and k_c >= 0):
            raise ValueError(f"HelixCable.core_torsional_stiffness_Nm2 must be finite and >= 0, got {k_c!r}")
        # a positive-definite compliance: restraining the twist must leave a positive stretch
        if self.core_twist_modulus ** 2 * k_c * self.core_area_m2 * self.core_modulus_Pa >= 1.0:
            raise ValueError("HelixCable: core_torsional_stiffness_Nm2 too large for the twist "
                             "modulus: G_c^2 K_c A_c E_c must be < 1")
        if not (self.conductor_yield_Pa > 0):
            raise ValueError(f"HelixCable.conductor_yield_Pa must be > 0, got {self.conductor_yield_Pa!r}")

    @classmethod
    def vaps_biw(cls) -> "HelixCable":
        """The B.I.W. VAPS cable of seed 004, section 4 (conductor E_i = 19.5 GPa).

        The conductor metal area (16 mm^2) is CABLE2's DATA value; the wire diameter
        (0.07 mm) is App. 4's figure for #22 AWG as printed; Poisson's ratio 0.34 is a
        handbook value for copper (the seed gives none). Conductor yield 68.9 MPa: annealed
        copper, Materials Selector (1978), as the seed quotes it. Twist free (slip ring, section 2).
        """
        return cls(core_area_m2=42.1e-6, core_modulus_Pa=81.4e9, core_twist_modulus=24.4e-6,
                   pitch_m=0.174, helix_radius_m=9.2e-3, conductor_modulus_Pa=19.5e9,
                   conductor_area_m2=16.0e-6, conductor_wire_diameter_m=0.07e-3,
                   poisson_ratio=0.34, core_twist_hand="left", conductor_yield_Pa=68.9e6)

    @property
    def lay_angle_rad(self) -> float:
        """Unstrained lay angle a = atan(2 pi R / P)."""
        return float(np.arctan(2.0 * np.pi * self.helix_radius_m / self.pitch_m))

    @cached_property
    def _axial_coefficients(self) -> tuple[float, float, float, float]:
        # (k, tan a, cos a, R G_c) so that e_c = k T and C'/P = tan a +/- R G_c T (c = 0)
        k = self.core_load_share / (self.core_area_m2 * self.core_modulus_Pa)
        tan_a = 2.0 * np.pi * self.helix_radius_m / self.pitch_m
        cos_a = 1.0 / np.sqrt(1.0 + tan_a * tan_a)
        rg = self.helix_radius_m * self.core_twist_modulus * self.core_load_share
        if self.twist_restraint == "restrained":  # no twist; e_c = T (1/(A_c E_c) - G_c^2 K_c)
            k = self.core_load_share * (1.0 / (self.core_area_m2 * self.core_modulus_Pa)
                                        - self.core_twist_modulus ** 2 * self.core_torsional_stiffness_Nm2)
            rg = 0.0
        return float(k), float(tan_a), float(cos_a), float(rg)

    @cached_property
    def _kernel_args(self) -> dict[str, tuple[float, float, float, float, float] | None]:
        # per lay, computed once: the monitor asks for them at every block
        if self.core_compressibility != 0.0 or self.twist_restraint == "limited":
            return {"left": None, "right": None}
        k, tan_a, cos_a, rg = self._axial_coefficients
        return {lay: (k, tan_a, cos_a, (1.0 if lay == self.core_twist_hand else -1.0) * rg,
                      self.conductor_modulus_Pa) for lay in ("left", "right")}


@dataclass(frozen=True)
class HelixSweep:
    """Result of a CABLE2/CABLE3-style design sweep at one core tension (SI units)."""

    helix_diameter_m: np.ndarray
    pitch_m: np.ndarray
    lay_angle_deg: np.ndarray
    lay_takeup: np.ndarray
    stress_left_Pa: np.ndarray
    stress_right_Pa: np.ndarray
    cable_load_left_N: np.ndarray
    cable_load_right_N: np.ndarray


def _check_lay(lay: str, what: str = "lay") -> None:
    if lay not in ("left", "right"):
        raise ValueError(f"{what} must be 'left' or 'right', got {lay!r}")


def _as_tension(tension_N: np.ndarray | float) -> np.ndarray:
    return _check_finite(np.asarray(tension_N, dtype=np.float64))


def _check_finite(t: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(t)):
        raise ValueError("tension_N contains NaN or inf")
    return t


def core_strain_twist(tension_N: np.ndarray | float, cable: HelixCable) -> tuple[np.ndarray, np.ndarray]:
    """Core strain e_c and twist per unit length theta / P [rad/m] at cable tension(s) [N].

    Seed 004 App. 1/4 (e_c = T / (A_c E_c), theta = G_c T P) under the cable's twist boundary
    condition (module docstring): free, restrained (theta = 0, e_c = T (1/(A_c E_c) - G_c^2 K_c))
    or limited (|theta / P| <= Phi / L, the excess held by the torque M = (theta/P - G_c T) K_c,
    which adds G_c M to e_c). T is the core's share of the tension. Vectorised.
    """
    share_t = cable.core_load_share * np.asarray(tension_N, dtype=np.float64)
    e_free = share_t / (cable.core_area_m2 * cable.core_modulus_Pa)
    twist_free = cable.core_twist_modulus * share_t
    if cable.twist_restraint == "free":
        return e_free, twist_free
    limit = 0.0 if cable.twist_restraint == "restrained" else cable.twist_limit_rad / cable.twist_length_m
    twist = np.clip(twist_free, -limit, limit)
    torque = (twist - twist_free) * cable.core_torsional_stiffness_Nm2
    return e_free + cable.core_twist_modulus * torque, twist


def _strained_geometry(t: np.ndarray, cable: HelixCable, sign: float, pitch, radius):
    """e_c, a, a' for tension t (broadcast against pitch and radius arrays)."""
    share_t = cable.core_load_share * t
    e_c, twist = core_strain_twist(t, cable)
    theta = twist * pitch
    r_strained = radius - cable.core_compressibility * share_t
    a = np.arctan(2.0 * np.pi * radius / pitch)
    a_s = np.arctan((2.0 * np.pi * r_strained + sign * r_strained * theta) / (pitch * (1.0 + e_c)))
    return e_c, a, a_s


def _lay_sign(lay: str, cable: HelixCable) -> float:
    _check_lay(lay)
    return 1.0 if lay == cable.core_twist_hand else -1.0


def conductor_stress(tension_N: np.ndarray | float, cable: HelixCable, lay: Lay = "left",
                     combined: bool = False) -> np.ndarray:
    """Conductor stress [Pa] for cable tension(s) ``tension_N`` [N] (seed 004 App. 4).

    ``lay`` is the conductor lay hand; it tightens the helix when equal to
    ``cable.core_twist_hand``. ``combined=False`` returns the axial (Knapp) stress,
    ``combined=True`` the ductile combination sqrt((sa + sb)^2 + 3 tau^2).
    Vectorised: returns a float64 array of the shape of ``tension_N``. The axial path
    runs as one compiled loop (plain Python without numba).
    """
    t = np.asarray(tension_N, dtype=np.float64)
    args = None if combined else axial_kernel_args(cable, lay)
    if args is None:
        return _stress_general(_check_finite(t), cable, _lay_sign(lay, cable), cable.pitch_m,
                               cable.helix_radius_m, combined)
    flat = t.reshape(-1)
    out = np.empty(flat.size)
    bad = (_loops.axial_compiled or _loops.axial_loop)(flat, *args, out)
    if bad >= 0:
        raise ValueError(f"tension_N contains NaN or inf, or is out of range (index {bad})")
    return out.reshape(t.shape)


def axial_kernel_args(cable: HelixCable, lay: Lay) -> tuple[float, float, float, float, float] | None:
    """(k, tan a, cos a, +-R G_c, E_i): the arguments of the compiled axial-stress kernel
    (``models.fatigue._loops.axial_stress``) for this cable and lay, or None when the axial
    stress needs the general formula (a compressible core, or limited twist: piecewise)."""
    try:
        return cable._kernel_args[lay]
    except (KeyError, TypeError):  # not a lay (TypeError: not even hashable)
        _check_lay(lay)
        raise


def _stress_general(t: np.ndarray, cable: HelixCable, sign: float, pitch, radius,
                    combined: bool) -> np.ndarray:
    terms = _stress_terms(t, cable, sign, pitch, radius, combined)
    if not combined:
        return terms[0]
    sigma_a, sigma_b, tau = terms
    return np.sqrt((sigma_a + sigma_b) ** 2 + 3.0 * tau ** 2)


def _stress_terms(t: np.ndarray, cable: HelixCable, sign: float, pitch, radius,
                  combined: bool = True) -> tuple[np.ndarray, ...]:
    """(sigma_a,) or (sigma_a, sigma_b, tau) of App. 4 (module docstring)."""
    e_c, a, a_s = _strained_geometry(t, cable, sign, pitch, radius)
    e_i = cable.conductor_modulus_Pa
    strain_ratio = np.cos(a) / np.cos(a_s) * (1.0 + e_c)
    sigma_a = e_i * np.abs(strain_ratio - 1.0)
    if not combined:
        return (sigma_a,)
    d_over_2r = cable.conductor_wire_diameter_m / (2.0 * radius)
    sigma_b = e_i * d_over_2r * np.sin(a) * (np.sin(a_s) - np.sin(a) * strain_ratio)
    g_i = e_i / (2.0 * (1.0 + cable.poisson_ratio))
    tau = g_i * np.abs(d_over_2r * np.sin(a) * np.cos(a) * (np.cos(a_s) / np.cos(a) - strain_ratio))
    return sigma_a, sigma_b, tau


def stress_terms(tension_N: np.ndarray | float, cable: HelixCable,
                 lay: Lay = "left") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """App. 4's axial, bending and shear stress (sigma_a, sigma_b, tau) [Pa] of the helix at
    tension(s) [N], before the ductile combination (``models.termination`` adds its bend to
    the normal stress). NaN/inf tension raises ValueError."""
    sigma_a, sigma_b, tau = _stress_terms(_as_tension(tension_N), cable, _lay_sign(lay, cable),
                                          cable.pitch_m, cable.helix_radius_m)
    return sigma_a, sigma_b, tau


def cable_load(tension_N: np.ndarray | float, stress_Pa: np.ndarray | float,
               cable: HelixCable) -> np.ndarray:
    """CABLE2/3 "cable load" [N]: core load plus conductor stress times conductor area.

    The listings multiply by COS(Alf) with Alf never assigned (= 0), i.e. by 1; so here.
    """
    return np.asarray(tension_N, dtype=np.float64) + np.asarray(stress_Pa) * cable.conductor_area_m2


def tension_for_stress(stress_Pa: np.ndarray | float, cable: HelixCable, lay: Lay = "left",
                       max_tension_N: float = 1e7) -> np.ndarray:
    """Core tension [N] at which the axial conductor stress equals ``stress_Pa``.

    The inverse of ``conductor_stress`` on [0, max_tension_N], where the stress grows
    monotonically with tension for practical cables; solved by vectorised bisection to
    machine precision. Used for the seed's "equivalent cable load" column.
    """
    s = np.asarray(stress_Pa, dtype=np.float64)
    if not np.all(np.isfinite(s)) or np.any(s < 0):
        raise ValueError("stress_Pa must be finite and >= 0")
    top = conductor_stress(max_tension_N, cable, lay)
    if np.any(s > top):
        raise ValueError(f"stress_Pa exceeds the stress at max_tension_N={max_tension_N} N ({top:.6g} Pa)")
    lo = np.zeros_like(s)
    hi = np.full_like(s, max_tension_N)
    for _ in range(200):  # bisection halves the bracket: 200 steps exhaust float64
        mid = 0.5 * (lo + hi)
        below = conductor_stress(mid, cable, lay) < s
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
        if np.all(hi - lo <= 4 * np.finfo(float).eps * np.maximum(hi, 1.0)):
            break
    return 0.5 * (lo + hi)


def _sweep(cable: HelixCable, tension_N: float, pitch: np.ndarray, radius: np.ndarray) -> HelixSweep:
    t = _as_tension(tension_N)
    pitch = np.asarray(pitch, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    if np.any(pitch <= 0) or np.any(radius <= 0):
        raise ValueError("pitches and helix diameters must be positive")
    stresses = {lay: _stress_general(t, cable, _lay_sign(lay, cable), pitch, radius, False)
                for lay in ("left", "right")}
    circumference = 2.0 * np.pi * radius
    pitch_b, radius_b = np.broadcast_arrays(pitch, radius)
    return HelixSweep(
        helix_diameter_m=2.0 * radius_b,
        pitch_m=pitch_b,
        lay_angle_deg=np.degrees(np.arctan(circumference / pitch)),
        lay_takeup=np.hypot(pitch, circumference) / pitch,
        stress_left_Pa=stresses["left"],
        stress_right_Pa=stresses["right"],
        cable_load_left_N=cable_load(t, stresses["left"], cable),
        cable_load_right_N=cable_load(t, stresses["right"], cable),
    )


def sweep_helix_diameter(cable: HelixCable, tension_N: float, diameters_m: np.ndarray) -> HelixSweep:
    """CABLE2: conductor stress versus helix diameter at the cable's pitch and one tension."""
    return _sweep(cable, tension_N, np.full(np.shape(diameters_m), cable.pitch_m),
                  0.5 * np.asarray(diameters_m, dtype=np.float64))


def sweep_pitch(cable: HelixCable, tension_N: float, pitches_m: np.ndarray) -> HelixSweep:
    """CABLE3: conductor stress versus pitch at the cable's helix radius and one tension."""
    pitches = np.asarray(pitches_m, dtype=np.float64)
    return _sweep(cable, tension_N, pitches, np.full(pitches.shape, cable.helix_radius_m))

