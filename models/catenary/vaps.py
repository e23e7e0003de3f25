"""The seed 004 (VAPS, 1981) single-point mooring as a multi-segment line definition."""

from __future__ import annotations

import math

from models.catenary.line import Joint, Line, Segment

G = 9.81
STEEL_DENSITY = 7850.0
STEEL_MODULUS = 2.0e11


def vaps_mooring(water_density: float = 1000.0, cable_mass: float = 1.10,
                 jacket_diameter: float = 0.080, jacket_density: float = 100.0,
                 seabed_friction: float = 0.0) -> Line:
    """Seed 004's mooring, anchor -> buoy: 2.5 m steel-rod bridle, 17.5 m of cable inside the
    flotation jacket, 20 m of bare cable (40 m anchor to buoy; the jacket covers the lower 20 m
    measured from the anchor, bridle included), in 23 m of water (use height = 23 m).

    Seed 004 gives no weights per metre; these are ASSUMPTIONS, derived from its text:
    - water: fresh (Lake Ontario / Lake Erie), `water_density` = 1000 kg/m^3.
    - bare cable, 31 mm overall (JSON `cable_overall_diameter_m`): displaces 0.755 kg/m; in-air
      mass `cable_mass` = 1.10 kg/m assumed (19x7 core 42.1 mm^2 steel ~0.33 kg/m, ten
      insulated conductor sets ~0.35 kg/m, neoprene jackets/tape/braid ~0.4 kg/m), giving a
      submerged weight of (1.10 - 0.755) * 9.81 = 3.4 N/m.
    - flotation jacket: ~80 mm over the jacket (seed 004 sec. 6 "approximately 80 mm diameter
      over the floatation jacket"), foam of `jacket_density` 100 kg/m^3 (closed-cell PE):
      net lift 3.84 kg/m, so the jacketed cable weighs 3.4 - 37.7 = -34.3 N/m (buoyant).
    - axial stiffness of the cable: the core, 42.1 mm^2 x 81.4 GPa = 3.43 MN.
    - bridle: 2.5 m steel rod of 11.1 kg (JSON `bridle_mass_kg`): 38.0 N/m submerged,
      EA = 200 GPa x (4.44 kg/m / 7850 kg/m^3).
    - strength-member fitting (14.4 kg dry, JSON `anchor_fitting_mass_kg`) with its floats: the
      seed says the assembly is "near neutral", so the joint carries a net float equal to the
      bridle's submerged weight (fitting + floats + bridle weigh nothing in water). The dry mass
      is kept on the Joint for added/virtual-mass models.
    """
    for name, value in (("water_density", water_density), ("cable_mass", cable_mass),
                        ("jacket_diameter", jacket_diameter), ("jacket_density", jacket_density)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    d_cable = 0.031
    a_cable = math.pi / 4.0 * d_cable**2
    if jacket_diameter <= d_cable:
        raise ValueError(f"jacket_diameter must exceed the 31 mm cable, got {jacket_diameter!r}")
    w_cable = (cable_mass - water_density * a_cable) * G
    a_foam = math.pi / 4.0 * (jacket_diameter**2 - d_cable**2)
    w_jacketed = w_cable - (water_density - jacket_density) * a_foam * G
    ea_cable = 4.21e-5 * 81.4e9
    bridle_length = 2.5
    rod_mass = 11.1 / bridle_length
    w_rod = rod_mass * G * (1.0 - water_density / STEEL_DENSITY)
    ea_rod = STEEL_MODULUS * rod_mass / STEEL_DENSITY
    return Line(
        segments=(Segment(bridle_length, w_rod, ea_rod, "bridle"),
                  Segment(20.0 - bridle_length, w_jacketed, ea_cable, "floated cable"),
                  Segment(20.0, w_cable, ea_cable, "bare cable")),
        joints=(Joint(-w_rod * bridle_length, 14.4, "strength-member fitting + floats"),
                Joint(0.0, 0.0, "end of flotation jacket")),
        seabed=True, seabed_friction=seabed_friction)


VAPS_DEPTH = 23.0  # m, seed 004 sec. 2 (fairlead height above the anchor at calm water)
