"""WAVFOR (seed 004 App. 6): all 22 printed rows to the printed digits."""

import json
from pathlib import Path

import numpy as np
import pytest

from models.wavfor import SEED004_TABLE_SLOPE_S_PER_M, WavforBuoy, seed004_period, wavfor

SHARED = next(
    (p / "shared" for p in Path(__file__).resolve().parents if (p / "shared/reference").is_dir()),
    None,
)
pytestmark = pytest.mark.skipif(SHARED is None, reason="../shared (seed reference data) absent")


@pytest.fixture(scope="module")
def ref():
    return json.loads((SHARED / "reference/seed004_vaps_cable.json").read_text())


@pytest.mark.parametrize("where", ["crest", "node"])
def test_printed_table_to_the_digit(ref, where):
    rows = np.array(ref["wavfor_cases_height_period_wavelength"])
    res = wavfor(rows[:, 0], rows[:, 1], wave_length=rows[:, 2])
    force = getattr(res, where)
    got = np.c_[force.total / 1e3, force.direction_deg, force.horizontal / 1e3, force.vertical / 1e3]
    expected = np.array(ref[f"wavfor_{where}_kN_deg_horz_vert"])
    # Printed with two decimals: the rounded value must equal the printed one in every cell.
    np.testing.assert_array_equal(np.round(got, 2), expected)


def test_dispersion_default_and_site_rule(ref):
    rows = np.array(ref["wavfor_cases_height_period_wavelength"])[1:]
    # The DATA periods follow 0.55 s per foot of height (+2.5 s), not the text's 1 s/m.
    t = seed004_period(rows[:, 0], SEED004_TABLE_SLOPE_S_PER_M)
    np.testing.assert_allclose(t, rows[:, 1], atol=0.01)  # heights printed to 1 cm
    assert seed004_period(1.5) == 4.0
    # Without the listing's wavelengths (dispersion instead) forces stay within 1 %.
    a = wavfor(rows[:, 0], rows[:, 1], wave_length=rows[:, 2]).max_force
    b = wavfor(rows[:, 0], rows[:, 1]).max_force
    np.testing.assert_allclose(b, a, rtol=0.01)
    # At 1.52 m (the field-failure wave) the crest bound (7.23 kN) exceeds the node one (7.01).
    assert wavfor(1.52, 5.25, wave_length=42.88).max_force == pytest.approx(7230, abs=5)


def test_bad_inputs():
    with pytest.raises(ValueError, match="height"):
        wavfor(-1.0, 5.0)
    with pytest.raises(ValueError, match="period"):
        wavfor(1.0, float("nan"))
    with pytest.raises(ValueError, match="WavforBuoy.volume"):
        WavforBuoy(volume=0.0)
