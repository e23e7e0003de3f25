"""The compiled fatigue loops' building blocks: deterministic log/exp and turning points.

``log_det``/``exp_det`` against numpy's log/exp (1 ulp), compiled == Python/numpy bit for
bit (no fused multiply-add, no fast-math), and the same bits whichever position an
element has in a vectorised loop (so chunking cannot change a cycle's damage). The
branch-free turning-point passes against a plain per-sample reference.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.fatigue import _loops as loops
from models._jit import HAVE_NUMBA, numba_module

needs_numba = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed")


def _compiled_map(func):
    numba = numba_module()  # registers the jitable building blocks

    @numba.njit(error_model="numpy")
    def apply(x, out):
        for i in range(x.shape[0]):
            out[i] = func(x[i])
    return apply


def _ulps(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.abs(got - ref) / np.spacing(np.abs(ref))


@pytest.fixture(scope="module")
def log_args() -> np.ndarray:
    rng = np.random.default_rng(1)
    return np.concatenate((np.exp(rng.uniform(-744.0, 709.0, 200_000)), rng.uniform(0.5, 2.0, 100_000),
                           rng.uniform(1.0, 200.0, 100_000)))  # the S-N curves' MPa


@pytest.fixture(scope="module")
def exp_args() -> np.ndarray:
    rng = np.random.default_rng(2)
    return np.concatenate((rng.uniform(-745.0, 709.7, 200_000), rng.uniform(-1.0, 1.0, 100_000),
                           rng.uniform(-60.0, 0.0, 100_000)))  # damage per cycle: e**-60 ... 1


def test_log_within_one_ulp_of_numpy(log_args):
    got = loops.log_det(log_args)
    ref = np.log(log_args)
    assert _ulps(got, ref).max() <= 1.0
    assert np.mean(got == ref) > 0.95  # mostly correctly rounded
    # hand values and the edges of the domain
    special = np.array([1.0, 2.0, math.e, 0.0, 5e-324, 1e-310, 2.2250738585072014e-308, np.inf, -1.0, np.nan])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        got = loops.log_det(special)
    assert got[0] == 0.0 and got[1] == math.log(2.0) and got[2] == pytest.approx(1.0, abs=2e-16)
    assert got[3] == -np.inf and got[7] == np.inf and np.isnan(got[8]) and np.isnan(got[9])
    np.testing.assert_allclose(got[4:7], [math.log(5e-324), math.log(1e-310), math.log(2.2250738585072014e-308)],
                               rtol=2e-16)


def test_exp_within_one_ulp_of_numpy(exp_args):
    got = loops.exp_det(exp_args)
    ref = np.exp(exp_args)
    normal = ref >= 2.2250738585072014e-308
    assert _ulps(got[normal], ref[normal]).max() <= 1.0
    assert np.mean(got == ref) > 0.85
    # subnormal results are rounded once: within one subnormal step
    assert np.abs(got[~normal] - ref[~normal]).max() <= 5e-324
    special = np.array([0.0, 1.0, -np.inf, np.inf, np.nan, 709.78, 709.79, -745.2, -2000.0, 2000.0])
    with np.errstate(over="ignore"):
        got = loops.exp_det(special)
    assert got[0] == 1.0 and got[1] == pytest.approx(math.e, rel=2e-16)
    assert got[2] == 0.0 and got[3] == np.inf and np.isnan(got[4])
    assert got[5] == pytest.approx(math.exp(709.78), rel=2e-16) and got[6] == np.inf
    assert got[7] == 0.0 and got[8] == 0.0 and got[9] == np.inf


@needs_numba
@pytest.mark.parametrize("name", ["log_det", "exp_det"])
def test_compiled_equals_numpy_bit_for_bit_at_any_position(name, log_args, exp_args):
    func = getattr(loops, name)
    x = log_args if name == "log_det" else exp_args
    x = np.concatenate((x, [0.0, 5e-324, np.inf, np.nan]))
    apply = _compiled_map(func)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        expected = func(x)
    out = np.empty_like(x)
    apply(x, out)
    np.testing.assert_array_equal(out, expected)  # NaN == NaN here
    # vectorised bodies and scalar remainders round alike: shift the data by 0..8 positions
    for shift in range(1, 9):
        apply(x[shift:shift + 1001], out[:1001])
        np.testing.assert_array_equal(out[:1001], expected[shift:shift + 1001])


def _reference_turning_points(x, cand, dirn, hyst):
    """The per-sample definition: extend while the signal keeps its direction, confirm
    when it retreats by more than ``hyst``."""
    tp = []
    for v in x:
        d = (v - cand) * dirn
        if -d > hyst:
            tp.append(cand)
            dirn = -dirn
            cand = v
        elif d > 0.0:
            cand = v
    return tp, cand, dirn


@pytest.mark.parametrize("hyst", [0.0, 0.5, 2.0])
def test_turning_points_match_the_per_sample_definition(hyst):
    rng = np.random.default_rng(7)
    # rounded noise: plateaus, exact repeats and signed zeros
    x = np.round(rng.normal(size=3000) * 3.0) * rng.choice([1.0, 1.0, 0.0], 3000)
    x[x == 0.0] = rng.choice([0.0, -0.0], int(np.sum(x == 0.0)))
    for compiled in (False, True):
        if compiled and not HAVE_NUMBA:
            continue
        tp_func = (numba_module().njit(loops._turning_points) if compiled else loops._turning_points)
        for start, dirn in ((0.0, 1.0), (-0.0, -1.0), (4.0, -1.0)):
            tp = np.empty(x.size)
            m, cand, d = tp_func(x, start, dirn, hyst, tp)
            ref_tp, ref_cand, ref_dirn = _reference_turning_points(x, start, dirn, hyst)
            assert m == len(ref_tp) > 100
            assert tp[:m].tobytes() == np.array(ref_tp).tobytes()  # signs of zeros too
            assert (cand, d) == (ref_cand, ref_dirn)
            assert math.copysign(1.0, cand) == math.copysign(1.0, ref_cand)
