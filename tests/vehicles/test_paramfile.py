"""Ground-station parameter files: `.parm` (Mission Planner / MAVProxy) and `.params` (QGroundControl)."""

from __future__ import annotations

import struct

from hypothesis import given
from hypothesis import strategies as st
from pymavlink import mavparm

from mavtune.vehicles.mavlink.paramfile import parm_text, qgc_text, write_param_files

names = st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZ_0123456789", min_size=1, max_size=16).filter(
    lambda n: n[0].isalpha())
float32 = st.floats(-1e6, 1e6, width=32)


@given(st.dictionaries(names, float32, min_size=1, max_size=8))
def test_parm_round_trips_through_pymavlinks_reader(tmp_path_factory, params):
    path = tmp_path_factory.mktemp("parm") / "tuned.parm"
    path.write_text(parm_text(params, "mavtune test"))
    loaded = mavparm.MAVParmDict()
    assert loaded.load(str(path), use_excludes=False)
    for name, value in params.items():
        assert struct.pack("<f", loaded[name]) == struct.pack("<f", value)  # the float32 exactly


def test_qgc_file_has_its_header_and_tab_separated_rows(tmp_path):
    paths = write_param_files(tmp_path, "tuned", {"PSC_POSZ_P": 2.625, "PSC_VELZ_P": 6.6875}, system_id=3,
                              component_id=1, stack="ardupilot")
    assert [p.name for p in paths] == ["tuned.parm", "tuned.params"]
    lines = (tmp_path / "tuned.params").read_text().splitlines()
    assert "# Vehicle-Id Component-Id Name Value Type" in lines
    rows = [line.split("\t") for line in lines if not line.startswith("#")]
    assert rows == [["3", "1", "PSC_POSZ_P", "2.625", "9"], ["3", "1", "PSC_VELZ_P", "6.6875", "9"]]
    assert qgc_text({"A": 1.0}).startswith("# Onboard parameters for Vehicle 1")
