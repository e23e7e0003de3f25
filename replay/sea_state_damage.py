"""The physics model's damage rate per sea state, per configured component.

For each sea state (Hs, Tp) the simulator (:mod:`replay.simulate`, the load model of
``buoymon simulate``: ``catenary`` dynamics or the seed 004 ``wavfor`` bound, on the seed
004 mooring) gives the noise-free cable tension, and each ``[[component]]`` of the
configuration turns it into stress and Miner damage exactly as the pipeline does
(:class:`monitor.components.Component`: helix or axial stress, its S-N curve with every
factor; rainflow with the residue counted as half cycles, ``models.fatigue.damage``).

Next to it, the Dirlik damage of the same stress's spectrum (Welch estimate,
:mod:`models.fatigue.spectral`) is a cross-check: a sea state where the two disagree by more
than a factor is one where the load is far from Gaussian (slack or snap loads, a load bound
clipped at zero), and the rainflow figure is the one to trust.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from models import fatigue
from models.fatigue.spectral import damage_rate_from_psd
from monitor.components import Component, build_cable
from monitor.config import Config
from replay.simulate import BASE_HZ, SimConfig, clean_tension


@dataclass(frozen=True)
class SeaStateDamage:
    """Damage per hour per component (rows) and sea state (columns), by rainflow of the
    simulated stress and by the Dirlik method on its spectrum; the peak tension (N)."""

    components: tuple[str, ...]
    rainflow_per_hour: NDArray[np.float64]
    dirlik_per_hour: NDArray[np.float64]
    max_tension_N: NDArray[np.float64]


def physics_damage(config: Config, hs_m: ArrayLike, tp_s: ArrayLike,
                   load_model: str = "wavfor", duration_s: float = 1200.0,
                   seed: int = 0) -> SeaStateDamage:
    """Simulate ``duration_s`` of each sea state (seed ``seed + index``: deterministic).

    Sea states with Hs = 0 produce no damage.
    """
    cable = build_cable(config)
    comps = [Component(c, cable, config.fatigue) for c in config.components]
    hs = np.atleast_1d(np.asarray(hs_m, dtype=float))
    tp = np.atleast_1d(np.asarray(tp_s, dtype=float))
    if hs.shape != tp.shape or hs.ndim != 1:
        raise ValueError("hs_m and tp_s must be 1-D and of the same length")
    rf = np.zeros((len(comps), hs.size))
    sp = np.zeros((len(comps), hs.size))
    peak = np.zeros(hs.size)
    hours = duration_s / 3600.0
    for k in np.flatnonzero(hs > 0):
        cfg = SimConfig(hours=hours, hs_m=float(hs[k]), tp_s=float(tp[k]), seed=seed + int(k),
                        depth_m=config.mooring.depth_m, load_model=load_model)
        tension = clean_tension(cfg)
        peak[k] = float(tension.max())
        for c, comp in enumerate(comps):
            stress = comp.stress(tension)
            rf[c, k] = fatigue.damage(stress, comp.sn_curve) / hours
            f, psd = signal.welch(stress, fs=BASE_HZ, nperseg=min(stress.size, 4096),
                                  detrend="constant")
            sp[c, k] = damage_rate_from_psd(comp.sn_curve, f[1:], psd[1:]) * 3600.0
    return SeaStateDamage(tuple(c.name for c in comps), rf, sp, peak)
