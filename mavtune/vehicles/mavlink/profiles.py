"""What differs between autopilots: MAVLink ids, flight modes, and the names, units, limits and loop (altitude or
horizontal) of position-controller gains."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError


class Autopilot(str, Enum):
    """The autopilot families mavtune knows how to tune."""

    PX4 = "px4"
    ARDUPILOT = "ardupilot"


@dataclass(frozen=True)
class ParamSpec:
    """One gain parameter as the autopilot knows it: default and hard limits in on-vehicle units."""

    name: str
    default: float
    min: float
    max: float


@dataclass(frozen=True)
class AutopilotProfile:
    """Everything autopilot-specific the MAVLink vehicle needs (modes by pymavlink name, parameter families)."""

    autopilot: Autopilot
    mav_autopilot: int
    flight_mode: str  # the mode mavtune flies the primitive in
    hold_mode: str  # a position-holding mode to leave the vehicle in when we started it in flight_mode
    allowed_modes: tuple[str, ...]  # modes the vehicle may be in when tuning starts
    stream_before_switch: bool  # PX4 OFFBOARD needs setpoints streaming before the switch
    families: tuple[tuple[tuple[str, float], ...], ...]  # aliases of one gain: (name, scale to family units)
    specs: tuple[ParamSpec, ...]  # every name that exists in some version, on-vehicle units

    def spec(self, name: str) -> ParamSpec | None:
        """The spec of a parameter name, or None when this autopilot has no such name."""
        return next((s for s in self.specs if s.name == name), None)

    def family(self, name: str) -> tuple[tuple[str, float], ...]:
        """All names of the gain `name` across autopilot versions, each with its unit scale."""
        for fam in self.families:
            if any(n == name for n, _ in fam):
                return fam
        return ((name, 1.0),)

    def mode_number(self, mode: str) -> tuple[int, int, int]:
        """(base_mode, custom_mode, custom_sub_mode) for MAV_CMD_DO_SET_MODE, from pymavlink's mode tables."""
        if self.autopilot is Autopilot.PX4:
            if mode not in mavutil.px4_map:
                raise MavtuneError(f"unknown PX4 mode {mode!r}; known: {', '.join(sorted(mavutil.px4_map))}")
            return mavutil.px4_map[mode]
        table = mavutil.mode_mapping_byname(mavlink.MAV_TYPE_QUADROTOR)
        if mode not in table:
            raise MavtuneError(f"unknown ArduCopter mode {mode!r}; known: {', '.join(sorted(table))}")
        return mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, table[mode], 0

    def custom_mode_word(self, mode: str) -> int:
        """The HEARTBEAT custom_mode field for a mode (PX4 packs main/sub mode into bits 16-31)."""
        _, main, sub = self.mode_number(mode)
        if self.autopilot is Autopilot.PX4:
            return (main << 16) | (sub << 24)
        return main


PX4 = AutopilotProfile(
    autopilot=Autopilot.PX4,
    mav_autopilot=mavlink.MAV_AUTOPILOT_PX4,
    flight_mode="OFFBOARD",
    hold_mode="LOITER",  # AUTO.LOITER (Hold)
    allowed_modes=("POSCTL", "LOITER", "OFFBOARD"),
    stream_before_switch=True,
    families=tuple(((n, 1.0),) for n in ("MPC_Z_P", "MPC_Z_VEL_P_ACC", "MPC_Z_VEL_I_ACC", "MPC_Z_VEL_D_ACC",
                                         "MPC_XY_P", "MPC_XY_VEL_P_ACC", "MPC_XY_VEL_I_ACC")),
    specs=(
        ParamSpec("MPC_Z_P", 1.0, 0.1, 1.5),
        ParamSpec("MPC_Z_VEL_P_ACC", 4.0, 2.0, 15.0),
        ParamSpec("MPC_Z_VEL_I_ACC", 2.0, 0.2, 3.0),
        ParamSpec("MPC_Z_VEL_D_ACC", 0.0, 0.0, 2.0),
        # horizontal: @min/@max of mc_pos_control's MPC_XY_P, MPC_XY_VEL_P_ACC, MPC_XY_VEL_I_ACC
        ParamSpec("MPC_XY_P", 0.95, 0.0, 2.0),
        ParamSpec("MPC_XY_VEL_P_ACC", 1.8, 1.2, 5.0),
        ParamSpec("MPC_XY_VEL_I_ACC", 0.4, 0.0, 60.0),
    ),
)

# ArduCopter <= 4.6 names first; Copter 4.7 renamed them PSC_D_* and scaled the acceleration gains by 0.1.
# Limits: the @Range of AC_PosControl's parameter metadata (PSC_POSZ_P 1–3, PSC_VELZ_P 1–8, PSC_VELZ_I 0.02–1, kept
# from 0 because 0 is the default, PSC_ACCZ_P 0.2–1.5, _I 0–3, _D 0–0.4); PX4: @min/@max of mc_pos_control.
ARDUPILOT = AutopilotProfile(
    autopilot=Autopilot.ARDUPILOT,
    mav_autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
    flight_mode="GUIDED",
    # GUIDED holds the last position target once setpoints stop (ArduCopter times out velocity/acceleration targets
    # after 3 s); LOITER would follow the RC throttle stick — on SITL without RC it descends and lands (checked)
    hold_mode="GUIDED",
    allowed_modes=("GUIDED", "LOITER", "POSHOLD", "ALT_HOLD"),
    stream_before_switch=False,
    families=(
        (("PSC_POSZ_P", 1.0), ("PSC_D_POS_P", 1.0)),
        (("PSC_VELZ_P", 1.0), ("PSC_D_VEL_P", 1.0)),
        (("PSC_VELZ_I", 1.0), ("PSC_D_VEL_I", 1.0)),
        (("PSC_VELZ_D", 1.0), ("PSC_D_VEL_D", 1.0)),
        (("PSC_ACCZ_P", 1.0), ("PSC_D_ACC_P", 0.1)),
        (("PSC_ACCZ_I", 1.0), ("PSC_D_ACC_I", 0.1)),
        (("PSC_ACCZ_D", 1.0), ("PSC_D_ACC_D", 0.1)),
        (("PSC_POSXY_P", 1.0), ("PSC_NE_POS_P", 1.0)),
        (("PSC_VELXY_P", 1.0), ("PSC_NE_VEL_P", 1.0)),
        (("PSC_VELXY_I", 1.0), ("PSC_NE_VEL_I", 1.0)),
        (("PSC_VELXY_D", 1.0), ("PSC_NE_VEL_D", 1.0)),
    ),
    specs=(
        ParamSpec("PSC_POSZ_P", 1.0, 1.0, 3.0),
        ParamSpec("PSC_VELZ_P", 5.0, 1.0, 8.0),
        ParamSpec("PSC_VELZ_I", 0.0, 0.0, 1.0),
        ParamSpec("PSC_VELZ_D", 0.0, 0.0, 1.0),
        ParamSpec("PSC_ACCZ_P", 0.5, 0.2, 1.5),
        ParamSpec("PSC_ACCZ_I", 1.0, 0.0, 3.0),
        ParamSpec("PSC_ACCZ_D", 0.0, 0.0, 0.4),
        ParamSpec("PSC_D_POS_P", 1.0, 1.0, 3.0),
        ParamSpec("PSC_D_VEL_P", 5.0, 1.0, 8.0),
        ParamSpec("PSC_D_VEL_I", 0.0, 0.0, 1.0),
        ParamSpec("PSC_D_VEL_D", 0.0, 0.0, 1.0),
        ParamSpec("PSC_D_ACC_P", 0.05, 0.02, 0.15),
        ParamSpec("PSC_D_ACC_I", 0.1, 0.0, 0.3),
        ParamSpec("PSC_D_ACC_D", 0.0, 0.0, 0.04),
        # horizontal (AC_PosControl @Range: _POSXY_P 0.5–2, _VELXY_P 0.1–6, _VELXY_I 0.02–1 kept from 0 as the
        # vertical one, _VELXY_D 0–1); later Copter renames them PSC_NE_POS_* / PSC_NE_VEL_*, same units
        ParamSpec("PSC_POSXY_P", 1.0, 0.5, 2.0),
        ParamSpec("PSC_VELXY_P", 2.0, 0.1, 6.0),
        ParamSpec("PSC_VELXY_I", 1.0, 0.0, 1.0),
        ParamSpec("PSC_VELXY_D", 0.5, 0.0, 1.0),
        ParamSpec("PSC_NE_POS_P", 1.0, 0.5, 2.0),
        ParamSpec("PSC_NE_VEL_P", 2.0, 0.1, 6.0),
        ParamSpec("PSC_NE_VEL_I", 1.0, 0.0, 1.0),
        ParamSpec("PSC_NE_VEL_D", 0.5, 0.0, 1.0),
    ),
)

PROFILES = {Autopilot.PX4: PX4, Autopilot.ARDUPILOT: ARDUPILOT}

HORIZONTAL_PREFIXES = ("MPC_XY_", "PSC_POSXY_", "PSC_VELXY_", "PSC_NE_")
ALTITUDE_PREFIXES = ("MPC_Z_", "PSC_POSZ_", "PSC_VELZ_", "PSC_ACCZ_", "PSC_D_")
NEWER_ARDUPILOT_PREFIXES = ("PSC_D_", "PSC_NE_")
"""Copter's later names (PSC_D_* for the up axis, PSC_NE_* for north-east) of the PSC_*Z_* / PSC_*XY_* gains."""


def param_loop(name: str) -> str | None:
    """The position-controller loop a gain parameter belongs to: "altitude", "horizontal", or None (not known)."""
    if name.startswith(HORIZONTAL_PREFIXES):
        return "horizontal"
    if name.startswith(ALTITUDE_PREFIXES):
        return "altitude"
    return None


def profile_for(autopilot: Autopilot | str) -> AutopilotProfile:
    """The profile of an autopilot by name ("px4" or "ardupilot")."""
    try:
        return PROFILES[Autopilot(autopilot)]
    except ValueError:
        raise MavtuneError(f"unknown autopilot {autopilot!r}; use px4 or ardupilot") from None


def profile_from_heartbeat(mav_autopilot: int) -> AutopilotProfile:
    """The profile matching a HEARTBEAT's autopilot field; any other autopilot is refused."""
    for profile in PROFILES.values():
        if profile.mav_autopilot == mav_autopilot:
            return profile
    raise MavtuneError(
        f"vehicle reports autopilot {mav_autopilot} (MAV_AUTOPILOT); mavtune tunes PX4 (12) and ArduPilot (3) only"
    )
