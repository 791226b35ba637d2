"""run_coordinator: result.json is written even when the run fails (the events must not be lost)."""

from __future__ import annotations

import json

import pytest

from mavtune.errors import MavtuneError
from mavtune.swarm import SwarmConfig, run_coordinator

from .conftest import free_port

pytestmark = pytest.mark.timeout(30)


def test_a_run_that_fails_still_writes_result_json(tmp_path):
    config = SwarmConfig(session="r1", token="x", presence_timeout_s=0.5)
    with pytest.raises(MavtuneError, match="0 of 2 vehicles"):
        run_coordinator(f"tcp/127.0.0.1:{free_port()}", 2, tmp_path, config=config, initial={"kd": 0.2})
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["gains"] is None and "0 of 2 vehicles" in result["error"] and result["session"] == "r1"
