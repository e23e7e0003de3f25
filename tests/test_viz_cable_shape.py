"""The 3D cable shape from the catenary models (models.catenary, issue 4)."""

from __future__ import annotations

import numpy as np
import pytest

from models.catenary import VAPS_DEPTH, solve, vaps_mooring
from monitor.viz.cable_shape import catenary_shape_provider
from monitor.viz.rerun_options import RerunOptions
from monitor.viz.rerun_outputs import open_recording
from monitor.viz.rerun_sink import RerunSink
from tests.viz_helpers import make_steps, read_rrd


def test_profile_ends_at_the_fairlead_with_the_requested_tension(tmp_path):
    line = vaps_mooring()
    shape = catenary_shape_provider(line, VAPS_DEPTH)
    x, z = shape(5000.0)
    assert x[0] == pytest.approx(0.0, abs=1e-9) and z[0] == pytest.approx(0.0, abs=1e-9)
    assert z[-1] == pytest.approx(VAPS_DEPTH, rel=1e-6)
    # forward check: solving the line at the profile's end point gives the same top tension
    assert float(solve(line, x[-1], z[-1]).t_top) == pytest.approx(5000.0, rel=1e-6)
    with pytest.raises(ValueError):
        shape(-1.0)
    with pytest.raises(ValueError, match="height"):
        catenary_shape_provider(line, 0.0)

    opts = RerunOptions(bearing_deg=0.0)
    sink = RerunSink(open_recording("B1", opts, rrd=tmp_path / "s.rrd"), opts,
                     shape_provider=shape)
    steps = make_steps(3)
    for s in steps:
        sink.on_step(s)
    sink.close()
    strip = np.array(read_rrd(tmp_path / "s.rrd")["mooring/line"]["LineStrips3D:strips"][-1][0])
    xe, ze = shape(float(steps[-1].tension_N[-1]))
    # bearing 0 (north): the line lies in the y-z plane
    np.testing.assert_allclose(strip[:, 1], xe, rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(strip[:, 2], ze, rtol=1e-6, atol=1e-5)
