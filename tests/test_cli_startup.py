"""`mavtune --help` and `mavtune plan` start fast because they import nothing they do not use: no simulator
kernel (numba), no network (zenoh), no MAVLink, no plotting, and for the default plan no numpy or scipy either.
(How fast is measured in benchmarks/cli_startup.py, not here.)"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

NEVER = ("numba", "zenoh", "pymavlink", "matplotlib", "osqp", "numpy", "scipy", "mavtune.sim.kernel",
         "mavtune.swarm", "mavtune.vehicles", "mavtune.report")

PROBE = """
import contextlib, io, json, sys
from mavtune.cli import run_app
with contextlib.redirect_stdout(io.StringIO()):
    code = run_app(sys.argv[1:])
print(json.dumps([code, sorted(sys.modules)]))
"""


def imported_by(*args: str) -> tuple[int, set[str]]:
    """(exit status, every module imported) of `mavtune ARGS` in a fresh interpreter."""
    out = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, timeout=60,
                         check=True).stdout
    code, modules = json.loads(out.splitlines()[-1])
    return code, set(modules)


@pytest.mark.parametrize("args", [["--help"], ["plan"], ["tune", "--help"], ["--version"],
                                  ["plan", "--strategy", "split", "-n", "4"], ["bank", "--help"]])
def test_help_and_plan_import_no_simulator_network_mavlink_or_plotting(args):
    code, modules = imported_by(*args)
    assert code == 0
    loaded = sorted(m for m in modules if any(m == heavy or m.startswith(heavy + ".") for heavy in NEVER))
    assert not loaded, f"mavtune {' '.join(args)} imported {loaded}"


def test_the_probe_sees_a_heavy_import_when_there_is_one():
    """The check above can fail: the help of a MAVLink command loads its module, and MAVLink with it."""
    code, modules = imported_by("mavsim", "--help")
    assert code == 0 and "pymavlink" in modules
