"""The CiA 402 device control of one drive as tables: which controlword walks the drive from
each state towards the state the driver wants, and the fault reset's rising edges.

`controlword()` is a pure function of the drive's present state and what the driver wants
(enabled, quick stop, or neither: disabled); `FaultReset` keeps the edges of bit 7 that a
fault reset sends, `fault_reset_interval` apart, at most `fault_reset_attempts` per arming.
"""

from __future__ import annotations

import math
from typing import Callable

from hopper_ros.canbus.epos2_objects import Command, State

# CiA 402 states with the power stage off: what "disabled" means for this driver
DISABLED_STATES = frozenset({State.START, State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED,
                             State.READY_TO_SWITCH_ON, State.FAULT})
FAULT_STATES = frozenset({State.FAULT, State.FAULT_REACTION_ACTIVE_DISABLED, State.FAULT_REACTION_ACTIVE_ENABLED})

#: towards OPERATION ENABLED: the controlword for each state (None: not known yet)
ENABLE: dict[State | None, Command] = {
    None: Command.SHUTDOWN,
    State.START: Command.SHUTDOWN,
    State.NOT_READY_TO_SWITCH_ON: Command.SHUTDOWN,
    State.SWITCH_ON_DISABLED: Command.SHUTDOWN,
    State.READY_TO_SWITCH_ON: Command.SWITCH_ON_AND_ENABLE,
    State.SWITCHED_ON: Command.SWITCH_ON_AND_ENABLE,
    State.REFRESH: Command.SWITCH_ON_AND_ENABLE,
    State.MEASURE_INIT: Command.SWITCH_ON_AND_ENABLE,
    State.OPERATION_ENABLED: Command.SWITCH_ON_AND_ENABLE,
    State.QUICK_STOP_ACTIVE: Command.DISABLE_VOLTAGE,       # to SWITCH ON DISABLED, then up again
}
#: a quick stop (the command watchdog): from OPERATION ENABLED only, else the power stage off
QUICK_STOP: dict[State | None, Command] = {State.OPERATION_ENABLED: Command.QUICK_STOP}


def controlword(state: State | None, enable: bool, quick_stop: bool, fault_reset: Callable[[], int]) -> int:
    """The controlword for this instant. `enable`: the driver wants the drive enabled and may
    enable it; `quick_stop`: it is stopping the drive after a watchdog trip; otherwise disabled.
    In FAULT `fault_reset()` says the word (a reset edge or disable voltage)."""
    if state in FAULT_STATES:
        return fault_reset() if state is State.FAULT else Command.DISABLE_VOLTAGE
    if enable:
        return ENABLE[state]
    if quick_stop:
        return QUICK_STOP.get(state, Command.DISABLE_VOLTAGE)
    return Command.DISABLE_VOLTAGE


class FaultReset:
    """Rising edges of bit 7 while a reset is armed: at start-up, and after the command stream
    acknowledged a fault in operation with a disable command."""

    def __init__(self, attempts: int, interval: float):
        self.attempts, self.interval = attempts, interval
        self.armed = True
        self.edges = 0
        self._edge_at = -math.inf

    def arm(self) -> None:
        self.armed, self.edges = True, 0

    def disarm(self) -> None:
        self.armed, self.edges = False, 0

    def word(self, now: float, last_cw: int | None) -> tuple[int, bool]:
        """(controlword, gave up now): FAULT_RESET for `interval` from an edge, then disable
        voltage before the next edge; after `attempts` edges the reset disarms (True once)."""
        if not self.armed:
            return Command.DISABLE_VOLTAGE, False
        if last_cw is not None and last_cw & Command.FAULT_RESET:
            if now - self._edge_at < self.interval:
                return Command.FAULT_RESET, False
            return Command.DISABLE_VOLTAGE, False
        if self.edges >= self.attempts:
            self.armed = False
            return Command.DISABLE_VOLTAGE, True
        return Command.FAULT_RESET, False

    def sent(self, controlword: int, last_cw: int | None, now: float) -> None:
        """A controlword went out: a rising edge of bit 7 counts as an attempt."""
        if controlword & Command.FAULT_RESET and not (last_cw or 0) & Command.FAULT_RESET:
            self.edges += 1
            self._edge_at = now
