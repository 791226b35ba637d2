"""The constrained tracker (OSQP), the cost surface and the surface/bench commands."""

import numpy as np
import pytest
from typer.testing import CliRunner

from mavtune.cli import app
from mavtune.sim import surface as surf
from mavtune.sim.scenario import Scenario
from mavtune.sim.tracker import HORIZONTAL_LIMITS, VERTICAL_LIMITS, flight_reference, reference


@pytest.mark.parametrize("primitive", ["circle", "step", "figure8"])
def test_tracker_output_is_feasible_and_starts_at_rest(primitive):
    ref = reference(primitive, 8.0, 2.0)
    assert ref.shape == (800, 9)
    np.testing.assert_allclose(ref[0, 3:], 0.0, atol=1e-9)
    tol = 1e-3
    assert np.abs(ref[:, 5]).max() <= VERTICAL_LIMITS[0] + tol
    assert np.abs(ref[:, 8]).max() <= VERTICAL_LIMITS[1] + tol
    assert np.abs(ref[:, 3:5]).max() <= HORIZONTAL_LIMITS[0] + tol
    assert np.abs(ref[:, 6:8]).max() <= HORIZONTAL_LIMITS[1] + tol
    # consistent: position is the integral of velocity
    np.testing.assert_allclose(np.diff(ref[:, 2]) / 0.01, 0.5 * (ref[1:, 5] + ref[:-1, 5]), atol=0.02)
    assert reference(primitive, 8.0, 2.0) is ref  # cached


def test_flight_reference_prepends_the_settle_hover():
    ref = flight_reference("circle", 8.0, 1.0, 2.0)
    assert ref.shape == (900, 9)
    np.testing.assert_array_equal(ref[:100, :3], np.broadcast_to(ref[100, :3], (100, 3)))


def test_surface_is_computed_written_and_read(tmp_path):
    s = surf.compute_surface(grid=3, repeats=2, scenario=Scenario.default(), seed=1)
    assert s.mean.shape == (3, 3) and (s.n == 2).all()
    assert s.mean[0, 0] > s.mean[1, 1]  # no feedback at all is worst
    surf.write_csv(s, tmp_path / "s.csv")
    back = surf.read_csv(tmp_path / "s.csv")
    np.testing.assert_allclose(back.mean, s.mean, rtol=1e-7)


def test_surface_and_bench_commands(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["surface", "--grid", "3", "--repeats", "2", "--payload", "0.9", "--out",
                              str(tmp_path)])
    assert res.exit_code == 0, res.output
    header = (tmp_path / "surface.csv").read_text().splitlines()[0]
    assert header == "kp,kd,mean_cost,std_cost,n"
    assert (tmp_path / "surface.png").stat().st_size > 1000
    res = runner.invoke(app, ["bench", "--sizes", "1,8"])
    assert res.exit_code == 0, res.output
    assert "vehicle-steps/s" in res.output
