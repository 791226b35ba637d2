"""A coordinator run that fails still writes result.json: the drop-out events and the error are not lost."""

from __future__ import annotations

import json
import logging

import pytest

from mavtune.config import load_config
from mavtune.errors import MavtuneError
from mavtune.run import run

from .conftest import free_port

pytestmark = pytest.mark.timeout(30)


def test_a_run_that_fails_still_writes_result_json(tmp_path):
    config = load_config(None, {"fleet.kind": "zenoh", "tuning.vehicles": 2, "swarm.session": "r1",
                                "swarm.key": "a key of sixteen+ chars", "swarm.presence_timeout_s": 0.5,
                                "swarm.listen": f"tcp/127.0.0.1:{free_port()}"})
    with pytest.raises(MavtuneError, match="0 of 2 vehicles"):
        run(config, tmp_path, quiet=True)
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["status"] == "error" and result["gains"] is None
    assert "0 of 2 vehicles" in result["error"] and result["session"] == "r1" and result["events"] == []


def test_a_bad_endpoint_is_refused_before_a_run_folder_or_key_is_made(tmp_path, monkeypatch, capsys):
    from mavtune.cli import run_app

    monkeypatch.chdir(tmp_path)
    assert run_app(["tune", "-q", "--fleet", "zenoh", "--listen", "127.0.0.1:7447"]) == 2
    assert capsys.readouterr().err.strip() == ("error: config swarm.listen: not a Zenoh locator like "
                                               "tcp/127.0.0.1:7447 (got '127.0.0.1:7447')")
    assert not (tmp_path / "runs").exists()  # no folder, no swarm.key written for a run that cannot start
    assert run_app(["agent", "--connect", "localhost", "--id", "v1"]) == 2
    assert "swarm.connect: not a Zenoh locator" in capsys.readouterr().err


@pytest.mark.parametrize("args, problem", [
    (["--id", "../v1"], "vehicle id '../v1' must be 1-64 letters, digits, '_' or '-'"),  # (its state folder's name)
    (["--id", "v1", "--min-flight-s", "-3"], "--min-flight-s must be a wall time of 0 s or more, got -3.0"),
])
def test_an_agent_given_a_bad_id_or_flight_time_says_so_before_it_connects(tmp_path, capsys, caplog, args, problem):
    from mavtune.cli import run_app

    caplog.set_level(logging.INFO)
    assert run_app(["agent", "--connect", "tcp/127.0.0.1:9", "--key-file", str(tmp_path / "no.key"), *args]) == 2
    assert capsys.readouterr().err.strip() == f"error: {problem}"
    assert not [r for r in caplog.records if "connecting" in r.getMessage()]
