"""MAVLink identifiers, PX4's custom modes and the setpoint type masks (re-exported by
:mod:`swarmbox.hal.mavlink.codec`, the module the rest of the package imports them from).

The numbers in comments are MAVLink's, for reading packet dumps.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from swarmbox.api import FlightMode, Setpoint, SetpointKind

Vec3 = tuple[float, float, float]

# ---- identifiers --------------------------------------------------------------------------------
MSG = {name[len("MAVLINK_MSG_ID_"):]: value for name, value in vars(mavlink).items()
       if name.startswith("MAVLINK_MSG_ID_") and isinstance(value, int)}
CMD_SET_MODE = mavlink.MAV_CMD_DO_SET_MODE                      # 176
CMD_ARM_DISARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM           # 400
CMD_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF                       # 22
CMD_LAND = mavlink.MAV_CMD_NAV_LAND                             # 21
CMD_RTL = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH                  # 20
CMD_SET_MESSAGE_INTERVAL = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL  # 511
CMD_REQUEST_MESSAGE = mavlink.MAV_CMD_REQUEST_MESSAGE           # 512
CMD_INJECT_FAILURE = mavlink.MAV_CMD_INJECT_FAILURE             # 420
RESULT_ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
RESULT_TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
RESULT_DENIED = mavlink.MAV_RESULT_DENIED
RESULT_UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
RESULT_FAILED = mavlink.MAV_RESULT_FAILED
RESULT_IN_PROGRESS = mavlink.MAV_RESULT_IN_PROGRESS
RESULT_NAMES = {v: k[len("MAV_RESULT_"):].lower() for k, v in vars(mavlink).items()
                if k.startswith("MAV_RESULT_") and k != "MAV_RESULT_ENUM_END" and isinstance(v, int)}
COMMAND_NAMES = {CMD_SET_MODE: "set_mode", CMD_ARM_DISARM: "arm_disarm", CMD_TAKEOFF: "takeoff",
                 CMD_LAND: "land", CMD_RTL: "return_to_launch",
                 CMD_SET_MESSAGE_INTERVAL: "set_message_interval", CMD_REQUEST_MESSAGE: "request_message",
                 CMD_INJECT_FAILURE: "inject_failure"}
PREARM_CHECK_BIT = mavlink.MAV_SYS_STATUS_PREARM_CHECK          # SYS_STATUS health: ready to arm
ARMED_FLAG = mavlink.MAV_MODE_FLAG_SAFETY_ARMED                 # HEARTBEAT base_mode
CUSTOM_MODE_FLAG = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
LANDED_ON_GROUND = mavlink.MAV_LANDED_STATE_ON_GROUND
LANDED_IN_AIR = mavlink.MAV_LANDED_STATE_IN_AIR
LANDED_TAKEOFF = mavlink.MAV_LANDED_STATE_TAKEOFF
LANDED_LANDING = mavlink.MAV_LANDED_STATE_LANDING
FRAME_LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED
FORCE_MAVLINK2 = 2

# ---- PX4 custom modes: custom_mode = main << 16 | sub << 24 -------------------------------------


def px4_mode(main: int, sub: int = 0) -> int:
    return (main << 16) | (sub << 24)


def px4_main_sub(custom_mode: int) -> tuple[int, int]:
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


MODE_POSCTL = px4_mode(3)
MODE_OFFBOARD = px4_mode(6)
MODE_TAKEOFF = px4_mode(4, 2)
MODE_HOLD = px4_mode(4, 3)          # AUTO.LOITER, PX4's mode after boot
MODE_MISSION = px4_mode(4, 4)
MODE_RTL = px4_mode(4, 5)
MODE_LAND = px4_mode(4, 6)
MODE_NAMES = {MODE_POSCTL: "POSCTL", MODE_OFFBOARD: "OFFBOARD", MODE_TAKEOFF: "AUTO.TAKEOFF",
              MODE_HOLD: "AUTO.LOITER", MODE_MISSION: "AUTO.MISSION", MODE_RTL: "AUTO.RTL",
              MODE_LAND: "AUTO.LAND", px4_mode(1): "MANUAL", px4_mode(2): "ALTCTL", px4_mode(7): "STABILIZED"}
_AUTO_MODES = {MODE_OFFBOARD: FlightMode.OFFBOARD, MODE_TAKEOFF: FlightMode.TAKEOFF,
               MODE_LAND: FlightMode.LAND, MODE_RTL: FlightMode.RTL}


def mode_name(custom_mode: int) -> str:
    main, sub = px4_main_sub(custom_mode)
    return MODE_NAMES.get(custom_mode, f"{main}.{sub}")


def flight_mode(custom_mode: int, armed: bool, landed: bool) -> FlightMode:
    """SwarmBox's view of a PX4 mode: disarmed (or armed and idle on the ground) is IDLE."""
    if not armed:
        return FlightMode.IDLE
    mode = _AUTO_MODES.get(custom_mode)
    if mode is not None:
        return mode
    return FlightMode.IDLE if landed else FlightMode.HOLD


# ---- SET_POSITION_TARGET_LOCAL_NED type masks ---------------------------------------------------
_POS_IGNORE = 0b111
_VEL_IGNORE = 0b111 << 3
_ACC_IGNORE = 0b111 << 6
_FORCE = mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET
_YAW_IGNORE = mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
_YAW_RATE_IGNORE = mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
TYPE_MASK = {   # what each setpoint kind fills in; + _YAW_IGNORE when it carries no yaw
    SetpointKind.POSITION: _VEL_IGNORE | _ACC_IGNORE | _YAW_RATE_IGNORE,       # 2552
    SetpointKind.VELOCITY: _POS_IGNORE | _ACC_IGNORE | _YAW_RATE_IGNORE,       # 2503
    SetpointKind.ACCELERATION: _POS_IGNORE | _VEL_IGNORE | _YAW_RATE_IGNORE,   # 2111
}


def type_mask(sp: Setpoint) -> int:
    return TYPE_MASK[sp.kind] | (_YAW_IGNORE if sp.yaw_rad is None else 0)


def setpoint_of_target(mask: int, pos: Vec3, vel: Vec3, acc: Vec3, yaw_rad: float) -> Setpoint | None:
    """The setpoint a SET_POSITION_TARGET_LOCAL_NED asks for (position wins over velocity over
    acceleration, as PX4's offboard mode ranks them); None for a mask it cannot fly (force, nothing)."""
    yaw = None if mask & _YAW_IGNORE else float(yaw_rad)
    if mask & _FORCE:
        return None
    if not mask & _POS_IGNORE:
        return Setpoint(SetpointKind.POSITION, pos, yaw)
    if not mask & _VEL_IGNORE:
        return Setpoint(SetpointKind.VELOCITY, vel, yaw)
    if not mask & _ACC_IGNORE:
        return Setpoint(SetpointKind.ACCELERATION, acc, yaw)
    return None
