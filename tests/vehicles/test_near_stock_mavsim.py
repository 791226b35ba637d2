"""End-to-end: a MAVLink run (a `mavtune mavsim` PX4 process on UDP loopback) answers the flown point nearest the
vehicle's stock gains within noise by default, and result.json, the parameter files and report.md say which and why."""

from __future__ import annotations

import json
import math

import pytest

from mavlink_harness import fast_config, mavsim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(420)]  # mavsim may compile first

STOCK = {"kp": (1.0 - 0.1) / 1.4, "kd": (4.0 - 2.0) / 13.0}  # PX4's MPC_Z_P 1, MPC_Z_VEL_P_ACC 4 in [0.1, 1.5], [2, 15]


def test_a_vehicle_run_answers_nearest_stock_within_noise(tmp_path):
    from mavtune.config import load_config
    from mavtune.run import run

    with mavsim(autopilot="px4") as url:
        flags = {"fleet.kind": "mavlink", "mavlink": {**fast_config().model_dump(mode="json"), "urls": [url]},
                 "tuning.bootstraps": 1, "tuning.epsilon": 0.25}
        run(load_config(None, flags), tmp_path, quiet=True)
    summary = json.loads((tmp_path / "result.json").read_text())
    answer = summary["answer"]
    assert answer["rule"] == "nearest stock within noise" and answer["reason"]
    assert answer["stock"] == [pytest.approx(STOCK)]  # the originals read before tuning, normalised
    assert summary["gains"] == answer["gains"]  # the answer is what the run gives, its parameters and files too
    tuned = summary["tuned_params"][url]
    assert tuned == pytest.approx({"MPC_Z_P": 0.1 + 1.4 * answer["gains"]["kp"],
                                   "MPC_Z_VEL_P_ACC": 2.0 + 13.0 * answer["gains"]["kd"]})
    assert "MPC_Z_P" in (tmp_path / "tuned.params").read_text()
    assert all("range" in m or "limit" in m for m in answer["plain_range_edges"])  # where the optimum lay, if at one
    plain = answer["plain"]
    assert set(plain["gains"]) == {"kp", "kd"} and isinstance(plain["flown"], bool)
    flown = [p["gains"] for p in summary["points"]]
    best = answer["best"]
    assert best["gains"] in flown and float(best["se"]) >= 0
    if answer["moved"]:  # a flown point, the nearest stock of those within one se of the best's cost
        chosen = answer["chosen"]
        assert chosen["gains"] == answer["gains"] and chosen["gains"] in flown
        if all(p["mean_cost"] is not None and math.isfinite(float(p["mean_cost"])) for p in summary["points"]):
            d_best = math.dist([best["gains"][n] for n in STOCK], list(STOCK.values()))
            assert chosen["distance_from_stock"] <= d_best + 1e-9  # the best is one of the points it chose among
        # (not nearer stock than the plain optimum: that one, the surface's minimum, need not have been flown)
        assert float(chosen["cost"]) - float(best["cost"]) <= math.hypot(float(chosen["se"]), float(best["se"])) + 1e-9
    else:
        assert answer["gains"] == plain["gains"]
    report = (tmp_path / "report.md").read_text()
    assert "## Answer" in report and "the search's optimum (plain)" in report and "stock" in report
