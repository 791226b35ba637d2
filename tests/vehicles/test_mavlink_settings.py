"""Settings of a vehicle run that are wrong without any vehicle ([mavlink] table, URLs, gains against tuning.space,
modes of a named autopilot; a swarm run's [swarm] table) are one line before the plan is shown or a run folder is
made: no vehicle is contacted, nothing is written."""

from __future__ import annotations

import pytest

from tests.test_fuzz import cli

URL = 'urls = ["udpin:127.0.0.1:9"]\n'  # never contacted: every case is refused before connecting

REFUSED = [
    (URL + 'gain_set = "inner"\n',
     "config mavlink: unknown gain set 'inner'; known: altitude, altitude-inner, horizontal"),
    (URL + 'gain_set = "altitude"\n[mavlink.gains.kp]\nparam = "MPC_Z_P"\nmin = 0.1\nmax = 1.0\n',
     "config mavlink: give either gain_set or [mavlink.gains] tables, not both"),
    (URL + 'loop = "horizontal"\ngain_set = "altitude-inner"\n',
     "config mavlink: gain_set 'altitude-inner' tunes the altitude loop, but loop = 'horizontal' flies"),
    (URL + '[mavlink.gains.kp]\nparam = "MPC_XY_P"\nmin = 0.2\nmax = 2.0\n'
           '[mavlink.gains.kd]\nparam = "MPC_Z_VEL_P_ACC"\nmin = 2.0\nmax = 15.0\n',
     "config mavlink: gains.kd: MPC_Z_VEL_P_ACC is a altitude-loop gain, but loop = 'horizontal'"),
    (URL + '[mavlink.gains.kp]\nparam = "MPC_Z_P"\nmin = 0.1\nmax = 1.5\n'
           '[mavlink.gains.ka]\nparam = "MPC_Z_VEL_D_ACC"\nmin = 0.0\nmax = 2.0\n',
     "config tuning.space tunes kp, kd, but the [mavlink] gains are kp, ka; give tuning.space the same gains"),
    ('urls = ["bogus:14540"]\n', "MAVLink URL 'bogus:14540' is not understood"),
    ('urls = ["udpin:127.0.0.1:70000"]\n', "MAVLink URL 'udpin:127.0.0.1:70000' needs HOST:PORT with a port"),
    ('urls = ["udpin:127.0.0.1:9", "udpin:127.0.0.1:9"]\n', "the same MAVLink URL is given twice"),
    ('urls = ["udpin:127.0.0.1:9?target_system=3"]\ntarget_system = 2\n',
     "MAVLink URL 'udpin:127.0.0.1:9?target_system=3' says target_system 3, the config says 2"),
    (URL + "primitive_s = 0.5\n", "config mavlink.primitive_s: Input should be greater than or equal to 1"),
    (URL + 'autopilot = "px4"\n[mavlink.safety]\nallowed_modes = ["HOVER"]\n',
     "config mavlink.safety.allowed_modes: unknown PX4 mode 'HOVER'"),
]


@pytest.mark.parametrize("mavlink, expected", REFUSED)
def test_a_bad_mavlink_setting_is_one_line_before_the_plan_or_the_run_folder(tmp_path, mavlink, expected):
    path = tmp_path / "run.toml"
    path.write_text('[fleet]\nkind = "mavlink"\n[mavlink]\n' + mavlink)
    out = tmp_path / "run"
    code, stdout, err = cli("tune", "--config", str(path), "--out", str(out), "-q")
    assert code == 2 and err.startswith(f"error: {expected}"), err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "rounds" not in stdout  # the plan was not shown
    assert not out.exists()  # no run folder was made
    code, stdout, err = cli("plan", "--config", str(path))  # and no plan is given for a run that would be refused
    assert code == 2 and err.startswith(f"error: {expected}") and "rounds" not in stdout


def test_a_bad_swarm_setting_is_one_line_before_the_run_folder(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text('[fleet]\nkind = "zenoh"\n[swarm]\nlisten_on = "tcp/127.0.0.1:7947"\n')
    out = tmp_path / "run"
    code, stdout, err = cli("tune", "--config", str(path), "--out", str(out), "-q")
    assert code == 2 and err.strip() == "error: config swarm.listen_on: Extra inputs are not permitted " \
                                        "(got 'tcp/127.0.0.1:7947')"
    assert "rounds" not in stdout and not out.exists()


def test_a_resumed_folder_with_a_bad_setting_is_left_as_it_was(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text('[fleet]\nkind = "mavlink"\n[mavlink]\nurls = ["bogus:1"]\n')
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code, _, err = cli("tune", "--config", str(path), "--out", str(out), "-q")
    assert code == 2 and err.startswith("error: MAVLink URL 'bogus:1' is not understood")
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]  # no journal, config.json or result.json


def test_a_plan_needs_no_vehicle_url_yet(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text('[fleet]\nkind = "mavlink"\n[mavlink]\ngain_set = "altitude-inner"\n')
    code, stdout, err = cli("plan", "--config", str(path))
    assert code == 0 and "rounds" in stdout and "kp, kd, ka, ki" in stdout, err
    code, _, err = cli("tune", "--config", str(path), "--out", str(tmp_path / "run"), "-q")
    assert code == 2 and err.startswith("error: no MAVLink vehicle given") and not (tmp_path / "run").exists()
