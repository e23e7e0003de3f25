"""Conductor stress where a termination moulding fixes the conductors (issue 20).

Both failures of seed 004 were "very localized in the termination mouldings" (section 5).
There the conductors cannot slide along the core to share out a bend, so on top of the helix
stress (``models.helix``) they carry the bending strain of the bend the strain relief allows.

Bend geometry, seed 004 App. 3A (bend test over a mandrel): the cable's neutral axis runs on a
radius r_1 (mandrel radius + cable radius; at a termination, the bend radius the strain relief
forces), the conductor on r_2 = r_1 + R_i (R_i the helix radius). Over a bend angle theta:

    neutral arc  = r_1 theta,     conductor arc = r_2 theta     (App. 3A items 1-2)
    excess       = (r_2 - r_1) theta = R_i theta                (item 3)
    strain       = excess / gauge                                (item 5)

In the bend test the conductor slides over a gauge length (842.5 mm: the sample's straight
lengths along the lay, item 4). In a moulding it is locked at the bend, so the default gauge
is the neutral arc itself and the strain is R_i / r_1 (the outer conductor's fibre strain),
whatever the angle of a bend (0 when straight); a ``gauge_length_m`` models a conductor free to
slide that far.

Stress at the termination: sigma = SCF x sqrt((sigma_a + sigma_b + E_i eps_bend)^2 + 3 tau^2),
the ductile rule of App. 4 with the helix's axial, bending and shear terms
(``helix.conductor_stress(..., combined=True)``) and the bend as an added axial strain. The
stress concentration factor is the component's ``scf`` (``monitor`` applies it to the S-N curve
and to the yield check): default 1.0, because neither the seed nor the manufacturer gives one
for the BIW moulding and the seed's lab test (App. 2) already fails later than the unconcentrated
model predicts (``models.fatigue.lab_calibration``).

The static bend raises the mean and peak stress, not the range of a tension cycle; it matters
for yield (``HelixCable.conductor_yield_Pa``) and for a mean-stress correction.

Public API
----------
- ``TerminationBend`` (frozen dataclass: ``bend_radius_m``, ``bend_angle_rad``, ``gauge_length_m``)
- ``bend_arc_lengths(bend, helix_radius_m) -> (neutral, conductor)`` [m]
- ``bend_strain(bend, helix_radius_m) -> float``
- ``termination_stress(tension_N, cable, lay, bend) -> ndarray`` [Pa] (without the SCF)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from models._jit import compile_loop, jitable
from models.helix import HelixCable, Lay, axial_kernel_args, stress_terms


@dataclass(frozen=True)
class TerminationBend:
    """The bend a strain relief imposes where the moulding fixes the conductors (SI units).

    ``bend_radius_m`` is r_1, the radius of the cable's neutral axis over the bend;
    ``gauge_length_m`` the conductor length taking up the excess arc (None: the neutral arc,
    i.e. conductors locked at the bend).
    """

    bend_radius_m: float
    bend_angle_rad: float
    gauge_length_m: float | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.bend_radius_m) and self.bend_radius_m > 0):
            raise ValueError(f"TerminationBend.bend_radius_m must be finite and > 0, got {self.bend_radius_m!r}")
        if not (np.isfinite(self.bend_angle_rad) and 0 <= self.bend_angle_rad <= np.pi):
            raise ValueError(f"TerminationBend.bend_angle_rad must be in [0, pi], got {self.bend_angle_rad!r}")
        g = self.gauge_length_m
        if g is not None and not (np.isfinite(g) and g > 0):
            raise ValueError(f"TerminationBend.gauge_length_m must be finite and > 0, got {g!r}")


def bend_arc_lengths(bend: TerminationBend, helix_radius_m: float) -> tuple[float, float]:
    """(neutral arc r_1 theta, conductor arc (r_1 + R_i) theta) [m], seed 004 App. 3A items 1-2."""
    return (bend.bend_radius_m * bend.bend_angle_rad,
            (bend.bend_radius_m + helix_radius_m) * bend.bend_angle_rad)


def bend_strain(bend: TerminationBend, helix_radius_m: float) -> float:
    """Conductor bending strain (conductor arc - neutral arc) / gauge, seed 004 App. 3A items 3-5.

    With the default gauge (the neutral arc) this is R_i / r_1 for any bend, 0 when straight.
    """
    if bend.gauge_length_m is None:
        return float(helix_radius_m / bend.bend_radius_m) if bend.bend_angle_rad > 0 else 0.0
    neutral, conductor = bend_arc_lengths(bend, helix_radius_m)
    return float((conductor - neutral) / bend.gauge_length_m)


def termination_stress(tension_N: np.ndarray | float, cable: HelixCable, lay: Lay,
                       bend: TerminationBend) -> np.ndarray:
    """Conductor stress [Pa] in the termination at cable tension(s) [N], without the SCF.

    sqrt((sigma_a + sigma_b + E_i eps_bend)^2 + 3 tau^2) (seed 004 App. 4's ductile rule, the
    bend of App. 3A as an added axial strain). The helix terms follow the cable's twist
    boundary condition. NaN/inf tension raises ValueError. Where the helix's axial kernel
    applies (free or restrained twist, incompressible core) the terms are evaluated without
    trigonometry (``_stress``), in one compiled loop (plain Python without numba); otherwise
    by ``helix.stress_terms``.
    """
    sigma_bend = cable.conductor_modulus_Pa * bend_strain(bend, cable.helix_radius_m)
    args = axial_kernel_args(cable, lay)
    if args is None:  # limited twist or a compressible core: App. 4 with its trigonometry
        sigma_a, sigma_b, tau = stress_terms(tension_N, cable, lay)
        return np.sqrt((sigma_a + sigma_b + sigma_bend) ** 2 + 3.0 * tau ** 2)
    t = np.asarray(tension_N, dtype=np.float64)
    coefs = _coefficients(cable, args, sigma_bend)
    out = np.empty(t.size)
    loop: Callable = _loop_compiled() or _loop
    bad = loop(t.reshape(-1), *coefs, out)
    if bad >= 0:
        raise ValueError(f"tension_N contains NaN or inf, or is out of range (index {bad})")
    return out.reshape(t.shape)


def _coefficients(cable: HelixCable, args: tuple[float, float, float, float, float],
                  sigma_bend: float) -> tuple[float, ...]:
    """The per-sample formula's constants (see ``_stress``)."""
    k, tan_a, cos_a, rg, e_mod = args
    sin_a = tan_a * cos_a
    d_over_2r = cable.conductor_wire_diameter_m / (2.0 * cable.helix_radius_m)
    g_mod = e_mod / (2.0 * (1.0 + cable.poisson_ratio))
    return (k, tan_a, cos_a, rg, e_mod, e_mod * d_over_2r * sin_a, sin_a,
            g_mod * d_over_2r * sin_a * cos_a, sigma_bend)


@jitable
def _stress(t, k, tan_a, cos_a, rg, e_mod, c_bend, sin_a, c_shear, sigma_bend):
    """App. 4 without trigonometry, as the helix's axial kernel: with y = 1 + e_c = 1 + k T and
    x = C'/P = tan a +/- R G_c T, r = sqrt(x^2 + y^2) gives cos a' = y / r, sin a' = x / r and
    cos a / cos a' (1 + e_c) = cos a r. Then sigma_a = E_i |cos a r - 1|,
    sigma_b = E_i d/(2R) sin a (x / r - sin a cos a r),
    tau = G_i d/(2R) sin a cos a (y / (r cos a) - cos a r) (squared below, so no |.|)."""
    y = 1.0 + k * t
    x = tan_a + rg * t
    r = np.sqrt(x * x + y * y)
    ratio = cos_a * r
    normal = np.abs(ratio - 1.0) * e_mod + c_bend * (x / r - sin_a * ratio) + sigma_bend
    tau = c_shear * (y / (r * cos_a) - ratio)
    return np.sqrt(normal * normal + 3.0 * tau * tau)


def _loop(t, k, tan_a, cos_a, rg, e_mod, c_bend, sin_a, c_shear, sigma_bend, out):
    """``out[i] = _stress(t[i], ...)``; returns the first non-finite index or -1."""
    for i in range(t.shape[0]):
        out[i] = _stress(t[i], k, tan_a, cos_a, rg, e_mod, c_bend, sin_a, c_shear, sigma_bend)
    for i in range(t.shape[0]):
        if not math.isfinite(out[i]):
            return i
    return -1


@functools.cache
def _loop_compiled() -> Callable | None:
    """``_loop`` compiled on its first use, not at import: that would import numba
    (models._jit says what that costs) in commands that never run it."""
    return compile_loop(_loop)
