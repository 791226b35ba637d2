"""The constrained tracker (OSQP), the cost surface and the surface/bench commands."""

import numpy as np
import pytest
from typer.testing import CliRunner

from mavtune.cli import app
from mavtune.errors import MavtuneError
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
    jerk = np.diff(ref[:, 6:9], axis=0) / 0.01
    assert np.abs(jerk[:, :2]).max() <= HORIZONTAL_LIMITS[2] + 0.1
    assert np.abs(jerk[:, 2]).max() <= VERTICAL_LIMITS[2] + 0.1
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


def test_tracker_reference_is_not_delayed_by_a_step(monkeypatch):
    """With only the position weighted, a feasible target that starts at rest is followed at the same time
    index (a one-step slip would leave an error of v·dt ≈ 3 mm here)."""
    from mavtune.sim import tracker

    monkeypatch.setattr(tracker, "Q_ACC", 0.0)
    monkeypatch.setattr(tracker, "Q_JERK", 0.0)
    monkeypatch.setattr(tracker, "W_SNAP", 1e-6)  # any smaller and the QP is ill-conditioned at eps 1e-5
    s = np.arange(300) / 299.0
    target = 2.0 + 0.5 * s**4 * (35 - 84 * s + 70 * s**2 - 20 * s**3)  # 0.5 m in 3 s; v, a, jerk 0 at both ends
    pva = tracker._axis(target, 2.0, tracker.VERTICAL_LIMITS)
    assert np.abs(pva[:, 0] - target).max() < 2e-4


@pytest.mark.parametrize("text, problem", [
    ("", "no column 'kp'"),
    ("a,b\n1,2\n", "no column 'kp'"),
    ("kp,kd,mean_cost,std_cost,n\n", "not a full kp x kd grid"),
    ("kp,kd,mean_cost,std_cost,n\n0,0,x,1,2\n0,1,1,1,2\n1,0,1,1,2\n1,1,1,1,2\n", "line 2: not a row of numbers"),
    ("kp,kd,mean_cost,std_cost,n\n0,0,1,1\n", "line 2: not a row of numbers"),
    ("kp,kd,mean_cost,std_cost,n\n0,0,nan,1,2\n0,1,1,1,2\n1,0,1,1,2\n1,1,1,1,2\n", "line 2: a value is not finite"),
    ("kp,kd,mean_cost,std_cost,n\n0,0,1,1,2\n0,0,1,1,2\n1,0,1,1,2\n1,1,1,1,2\n", "each point once"),
])
def test_a_surface_csv_that_does_not_parse_is_one_line_error(tmp_path, text, problem):
    path = tmp_path / "s.csv"
    path.write_text(text)
    with pytest.raises(MavtuneError, match=problem) as err:
        surf.read_csv(path)
    assert "\n" not in str(err.value)
    with pytest.raises(MavtuneError, match="cannot read"):
        surf.read_csv(tmp_path)


@pytest.mark.parametrize("args, problem", [
    (["surface", "--grid", "1"], "grid >= 2"),
    (["surface", "--grid", "2", "--repeats", "0"], "repeats >= 1"),
    (["surface", "--grid", "100000"], "lower --grid or --repeats"),  # 2e11 flights: refused before any array
    (["surface", "--grid", "2", "--repeats", "1", "--payload", "-0.5"], "--payload"),
    (["surface", "--grid", "2", "--repeats", "1", "--cost", "rms"], "--cost"),
    (["bench", "--sizes", "1", "--primitive-s", "-1"], "--primitive-s"),
    (["bench", "--sizes", "1,x"], "--sizes"),
])
def test_bad_command_input_is_one_line_error_and_writes_nothing(tmp_path, args, problem):
    out = tmp_path / "out"
    res = CliRunner().invoke(app, [*args, *(["--out", str(out)] if args[0] == "surface" else [])])
    assert isinstance(res.exception, MavtuneError), res.output
    assert problem in str(res.exception) and "\n" not in str(res.exception)
    assert not out.exists()


def test_surface_into_a_file_or_unwritable_folder_is_one_line_error(tmp_path):
    (tmp_path / "f").write_text("")
    for out, problem in ((tmp_path / "f", "is a file"), (tmp_path / "f" / "sub", "cannot write")):
        res = CliRunner().invoke(app, ["surface", "--grid", "2", "--repeats", "1", "--out", str(out)])
        assert isinstance(res.exception, MavtuneError) and problem in str(res.exception)


@pytest.mark.parametrize("payload_kg", [0.0, 0.9])
def test_the_optimum_lies_inside_the_gain_square(payload_kg):
    """The normalised ranges put the surface minimum of the default and of the payload scenario inside [0, 1]²,
    not on an edge."""
    s = surf.compute_surface(grid=9, repeats=4, scenario=Scenario(payload_kg=payload_kg), seed=0)
    kp, kd = s.argmin()
    assert 0.0 < kp < 1.0 and 0.0 < kd < 1.0


def test_tracker_is_a_receding_horizon_that_sees_only_its_40_steps():
    """Re-planned every 0.01 s over 40 steps (0.01 s, then 0.2 s: 7.81 s ahead): changing the target later than
    that leaves the reference up to then unchanged, and changes it once the change comes into view."""
    from mavtune.sim import tracker

    assert tracker.horizon_steps_s().size == 40 and tracker.horizon_steps_s().sum() == pytest.approx(7.81)
    target = np.full(1200, 2.0)
    changed = target.copy()
    changed[1000:] = 2.5  # a step at t = 10 s
    a = tracker._axis(target, 2.0, tracker.VERTICAL_LIMITS)
    b = tracker._axis(changed, 2.0, tracker.VERTICAL_LIMITS)
    seen_from = 1000 - 781  # the first step whose horizon reaches t = 10 s
    np.testing.assert_array_equal(a[:seen_from], b[:seen_from])
    assert np.abs(a[seen_from:1000, 0] - b[seen_from:1000, 0]).max() > 1e-3  # MPC anticipates within its horizon


def test_circle_starts_at_rest_at_its_first_point_and_accelerates_within_the_limits():
    """No velocity jump: the settle hover and the tracker start at the primitive's first point at rest, and every
    step's change of velocity stays within the acceleration limit (the primitive itself starts at 0.79 m/s)."""
    ref = flight_reference("circle", 8.0, 1.0, 2.0)
    start = ref[100]
    np.testing.assert_allclose(start[3:], 0.0, atol=1e-12)
    dv = np.abs(np.diff(ref[:, 3:6], axis=0))
    assert dv[:, :2].max() <= HORIZONTAL_LIMITS[1] * 0.01 + 1e-4
    assert dv[:, 2].max() <= VERTICAL_LIMITS[1] * 0.01 + 1e-4
    assert np.linalg.norm(ref[150, 3:5]) > 0.1  # it does get going within half a second
