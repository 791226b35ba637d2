"""The 4-gain "altitude-inner" set on the autopilots' own SITLs (ArduCopter: PSC_POSZ_P, PSC_VELZ_P, PSC_ACCZ_P,
PSC_ACCZ_I; PX4 SIH: MPC_Z_P, MPC_Z_VEL_P_ACC, MPC_Z_VEL_D_ACC, MPC_Z_VEL_I_ACC): a short run completes, its four
tuned parameters lie in their ranges and are in tuned.parm, and reading the four back over MAVLink afterwards finds
the originals on the vehicle. Short: ε = 0.25, one bootstrap, one flight a point (no adaptive repeats)."""

from __future__ import annotations

import pytest
from pymavlink import mavparm

from mavtune.vehicles.mavlink.config import MavlinkConfig, gain_set_map
from mavtune.vehicles.mavlink.profiles import Autopilot

from mavlink_harness import tune_mavlink
from px4_harness import SKIP_REASON as PX4_SKIP, px4_root, px4_vehicles, read_px4_params
from sitl_harness import SKIP_REASON as SITL_SKIP, read_sitl_params, sitl_binary, sitl_vehicles

pytestmark = [pytest.mark.sitl, pytest.mark.slow, pytest.mark.integration, pytest.mark.timeout(900)]

SHORT = dict(bootstraps=1, epsilon=0.25, adaptive=False)


def check_run(result: dict, url: str, autopilot: Autopilot, folder) -> dict[str, float]:
    """The run finished, restored, and tuned all four parameters inside their ranges (also in tuned.parm);
    returns the originals it recorded."""
    assert result["status"] == "finished" and result["restored"] is True
    assert set(result["gains"]) == {"kp", "kd", "ka", "ki"}
    ranges = {c.param: (c.min, c.max) for c in gain_set_map("altitude-inner", autopilot).values()}
    tuned = result["tuned_params"][url]
    assert set(tuned) == set(ranges)
    for name, value in tuned.items():
        assert ranges[name][0] - 1e-6 <= value <= ranges[name][1] + 1e-6, (name, value)
    parm = mavparm.MAVParmDict()
    assert parm.load(str(folder / "tuned.parm"), use_excludes=False)
    assert {n: parm[n] for n in tuned} == pytest.approx(tuned, rel=1e-5)
    originals = result["original_params"][url]
    assert set(originals) == set(ranges)
    print(f"{autopilot.value}: {result['rounds']} rounds, gains {result['gains']}, tuned {tuned}")
    return originals


@pytest.mark.skipif(sitl_binary() is None, reason=SITL_SKIP)
def test_arducopter_sitl_tunes_the_inner_loop_and_restores_it(tmp_path):
    config = MavlinkConfig(gain_set="altitude-inner", param_timeout_s=0.5, heartbeat_wait_s=20.0)
    with sitl_vehicles(1) as (sitl,):
        result = tune_mavlink([sitl.tuner_url], tmp_path, config, **SHORT)
        originals = check_run(result, sitl.tuner_url, Autopilot.ARDUPILOT, tmp_path)
        assert read_sitl_params(sitl.tuner_url, list(originals)) == originals
    assert originals == pytest.approx({"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0, "PSC_ACCZ_P": 0.5, "PSC_ACCZ_I": 1.0})


@pytest.mark.skipif(px4_root() is None, reason=PX4_SKIP)
def test_px4_sitl_tunes_the_inner_loop_and_restores_it(tmp_path):
    config = MavlinkConfig(autopilot="px4", gain_set="altitude-inner", heartbeat_wait_s=30.0, primitive_s=4.0)
    with px4_vehicles(1) as (px4,):
        result = tune_mavlink([px4.tuner_url], tmp_path, config, **SHORT)
        originals = check_run(result, px4.tuner_url, Autopilot.PX4, tmp_path)
        assert read_px4_params(px4.tuner_url, list(originals)) == originals
    assert originals == pytest.approx({"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0, "MPC_Z_VEL_D_ACC": 0.0,
                                       "MPC_Z_VEL_I_ACC": 2.0})
