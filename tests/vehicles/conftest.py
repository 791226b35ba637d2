"""Every MAVLink test keeps its vehicles' originals records in its own state folder, never the user's."""

import pytest


@pytest.fixture(autouse=True)
def _own_state_folder(tmp_path_factory, monkeypatch):
    """$MAVTUNE_STATE_DIR for this test (also inherited by the processes it starts)."""
    monkeypatch.setenv("MAVTUNE_STATE_DIR", str(tmp_path_factory.mktemp("state")))
