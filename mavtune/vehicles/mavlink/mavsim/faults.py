"""Faults the MAVLink simulator can inject, parsed from `--fault` flags (for tests of the safety behaviour)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mavtune.errors import MavtuneError

FAULT_HELP = (
    "heartbeat-gap:N[:SECONDS] (link silent for SECONDS wall time, default 1, during primitive N), "
    "position-gap:N[:SECONDS] (no LOCAL_POSITION_NED or GLOBAL_POSITION_INT for SECONDS wall time, default 1, "
    "during primitive N; HEARTBEATs go on), "
    "mode-change:N (pilot switches mode during primitive N), "
    "param-drop:NAME:K (the K-th PARAM_SET changing NAME, and its retries, are never answered), "
    "diverge:NAME:VALUE (the altitude loop is unstable while NAME > VALUE), "
    "no-motor-outputs (neither SERVO_OUTPUT_RAW nor ACTUATOR_OUTPUT_STATUS is ever sent)"
)


@dataclass
class Faults:
    """The faults to inject; primitives are counted from 1 as the vehicle sees them start."""

    heartbeat_gap: tuple[int, float] | None = None  # (primitive number, wall seconds)
    position_gap: tuple[int, float] | None = None  # (primitive number, wall seconds): positions alone withheld
    mode_change: int | None = None  # primitive number
    param_drop: dict[str, int] = field(default_factory=dict)  # name → which value-changing PARAM_SET to drop
    diverge: dict[str, float] = field(default_factory=dict)  # name → threshold
    at_s: float = 0.5  # how far into the primitive (vehicle time) a timed fault strikes
    no_motor_outputs: bool = False  # an autopilot that reports no motor outputs


def parse_faults(specs: list[str] | None) -> Faults:
    """Faults from flag strings such as "mode-change:2"; MavtuneError naming the flag when one is malformed."""
    faults = Faults()
    for spec in specs or []:
        kind, *args = spec.split(":")
        try:
            if kind in ("heartbeat-gap", "position-gap") and len(args) in (1, 2):
                gap = float(args[1]) if len(args) == 2 else 1.0
                if not (gap > 0 and math.isfinite(gap)):
                    raise ValueError
                setattr(faults, kind.replace("-", "_"), (int(args[0]), gap))
            elif kind == "mode-change" and len(args) == 1:
                faults.mode_change = int(args[0])
            elif kind == "param-drop" and len(args) == 2:
                faults.param_drop[args[0]] = int(args[1])
            elif kind == "diverge" and len(args) == 2:
                faults.diverge[args[0]] = float(args[1])
            elif kind == "no-motor-outputs" and not args:
                faults.no_motor_outputs = True
            else:
                raise ValueError
        except ValueError:
            raise MavtuneError(f"--fault {spec!r} is not understood; use {FAULT_HELP}") from None
    return faults
