"""The horizontal loop (`loop = "horizontal"`) against both real autopilots' SITLs: ArduCopter (PSC_POSXY_P /
PSC_VELXY_P, at ×10) and PX4 SIH (MPC_XY_P / MPC_XY_VEL_P_ACC, real time). Short runs (ε = 0.25, one bootstrap);
each reads the horizontal gains back over MAVLink afterwards: the originals are on the vehicle again."""

from __future__ import annotations

import time

import pytest
from pymavlink import mavparm

from mavtune.vehicles.mavlink.config import gain_set_map, MavlinkConfig
from mavtune.vehicles.mavlink.params import as_float32
from mavtune.vehicles.mavlink.profiles import Autopilot

from mavlink_harness import tune_mavlink
from px4_harness import SKIP_REASON as PX4_SKIP, px4_root, px4_vehicles, read_px4_params
from sitl_harness import SKIP_REASON as SITL_SKIP, read_sitl_params, recorded_rounds, sitl_binary, sitl_vehicles

pytestmark = [pytest.mark.sitl, pytest.mark.slow, pytest.mark.integration, pytest.mark.timeout(900)]

SHORT = dict(bootstraps=1, epsilon=0.25, adaptive=False, design_split=False)  # a known number of rounds: the path is
# tested here (design_split = false: one vehicle flies each design point once, 43 rounds, not twice in turn, 61)


def check_run(result: dict, url: str, folder, originals: dict[str, float], autopilot: Autopilot) -> None:
    """A finished horizontal run: both xy gains tuned inside their ranges, written to the parameter files, and the
    originals recorded and restored."""
    assert result["status"] == "finished" and result["restored"] is True
    assert result["original_params"] == {url: originals}
    assert result["flights_by_status"]["ok"] > 0 and recorded_rounds(folder) == result["rounds"]
    tuned = result["tuned_params"][url]
    spans = {g.param: (g.min, g.max) for g in gain_set_map("horizontal", autopilot).values()}
    assert set(tuned) == set(originals) and all(spans[p][0] <= v <= spans[p][1] for p, v in tuned.items())
    parm = mavparm.MAVParmDict()
    assert parm.load(str(folder / "tuned.parm"), use_excludes=False)
    assert {n: parm[n] for n in tuned} == pytest.approx(tuned, rel=1e-6)
    for edge in result["range_edges"]:
        assert edge["param"] in originals and edge["param"] in edge["message"]


SETUPS = {  # autopilot: (its defaults, as stored; vehicles; reading parameters back; config)
    "ardupilot": ({"PSC_POSXY_P": 1.0, "PSC_VELXY_P": 2.0}, sitl_vehicles, read_sitl_params,  # AC_PosControl
                  MavlinkConfig(loop="horizontal", param_timeout_s=0.5, heartbeat_wait_s=20.0)),
    "px4": ({"MPC_XY_P": as_float32(0.95), "MPC_XY_VEL_P_ACC": as_float32(1.8)}, px4_vehicles,  # mc_pos_control
            read_px4_params, MavlinkConfig(loop="horizontal", autopilot="px4", heartbeat_wait_s=30.0)),
}


@pytest.mark.parametrize("autopilot", [
    pytest.param("ardupilot", marks=pytest.mark.skipif(sitl_binary() is None, reason=SITL_SKIP)),
    pytest.param("px4", marks=pytest.mark.skipif(px4_root() is None, reason=PX4_SKIP)),
])
def test_sitl_tunes_the_horizontal_loop_and_restores(tmp_path, autopilot):
    originals, vehicles, read_params, cfg = SETUPS[autopilot]
    with vehicles(1) as (vehicle,):
        started = time.monotonic()
        result = tune_mavlink([vehicle.tuner_url], tmp_path, cfg, **SHORT)
        wall_s = time.monotonic() - started
        assert read_params(vehicle.tuner_url, list(originals)) == originals
    check_run(result, vehicle.tuner_url, tmp_path, originals, Autopilot(autopilot))
    print(f"{autopilot} SITL, horizontal: {result['rounds']} rounds in {wall_s:.1f} s wall "
          f"({wall_s / result['rounds']:.1f} s a round), params {result['tuned_params'][vehicle.tuner_url]}")
