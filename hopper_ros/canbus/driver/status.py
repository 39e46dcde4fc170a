"""What the motor driver knows of the drive (`DriveStatus`), its phase (`Phase`), and how it reads
a bus failure (`connection_closed`, `first_line`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from hopper_ros.canbus.epos2_objects import State

from .settings import MODE_DISABLED


def connection_closed(exc: BaseException) -> bool:
    """Whether a bus error is the transport's connection closed by its other end (a socketcand hub
    that went away: reset, broken pipe): no later frame will pass, unlike a CAN error."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, (ConnectionResetError, BrokenPipeError, ConnectionAbortedError)):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def first_line(exc: BaseException) -> str:
    """An exception's message without the traceback some python-can errors carry in it."""
    text = str(exc).strip()
    return text.split("Traceback (most recent call last)")[0].strip().splitlines()[0] if text else type(exc).__name__


class Phase(str, Enum):
    STARTING = "starting"       # start-up sequence (NMT, SDO configuration) in progress
    RUNNING = "running"         # operational: SYNC, PDOs, state machine
    FAILED = "failed"           # start-up failed; retried after settings.startup_retry
    SHUTTING_DOWN = "shutting_down"
    STOPPED = "stopped"


@dataclass
class DriveStatus:
    """What the driver knows of the drive, SI units."""

    stamp: float = math.nan             # time of the TPDO it comes from
    state: State | None = None          # CiA 402 state (None: not known yet)
    statusword: int = 0
    operation_mode: int = 0             # modes of operation display (EPOS2: -3 current, -1 position)
    commanded_mode: int = MODE_DISABLED  # command being executed (MODE_*)
    position: float = math.nan          # leg angle [rad]
    velocity: float = math.nan          # leg angular velocity [rad/s]
    current: float = math.nan           # motor current [A]
    torque: float = math.nan            # hip torque [N m]
    fault_code: int = 0                 # last error code seen (EMCY / 0x603F), 0: none
    fault_text: str = ""
    heartbeat_ok: bool = False
    nmt_state: int | None = None

    @property
    def state_name(self) -> str:
        return "UNKNOWN" if self.state is None else self.state.value.replace("_", " ")
