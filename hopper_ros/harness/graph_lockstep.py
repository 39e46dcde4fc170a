"""The whole node graph's logic in one process, in lockstep with the simulated robot, no ROS.

Per 1 ms period, the same modules the nodes wrap, in the order the data flows:
sim_robot (SimRobot with its emulated EPOS2 on a python-can virtual bus) -> the UDP packet bytes
-> encoder bridge, state estimator, event detector (sensing.pipeline) -> the deadbeat
controller's stride policy (control.stride_policy, as the node runs it) -> motor driver (our
CANopen master on the same virtual bus) -> CAN frames that the emulated drive takes at the next
period. Each module sees exactly what its node would, minus the transport delays; a run is
deterministic and many times faster than real time. Used by the tests
to check the loop end to end (signs, units, timing) and by the benchmarks.

The host clock: the packet sampled at simulated time t reaches the sensing chain at host time
t + `host_delay(t)` (default 0; non-decreasing in t + delay). The controller and the motor driver's
command ages run on it, as the nodes run on the host's clock: a step of the delay is the simulated
robot's process stalled (beyond sim/runner.py's RESYNC_AFTER its world stands still and its drive
answers none of the SYNCs meanwhile; a shorter stall is caught up, the following samples in a burst,
the drive taking one SYNC period of frames a step), a large delay of the first packets a late start
(issue 29). An event at time t reaches the controller `event_delay(t)` later on the host clock, in
order, while its repeats run every period: the loop's container starved by a real-time process of
its priority, the repeating thread above it on time. `GraphRun.stances` is the stance ramp as the leg felt it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable, Iterable

import can

from hopper_ros.canbus.driver import DriverSettings, MotorDriver
from hopper_ros.canbus.driver.settings import ERROR
from hopper_ros.canbus.epos2_emulator import Epos2Emulator
from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.sensing.pipeline import SensingPipeline
from hopper_ros.sensing.samples import EventType
from hopper_ros.sim.robot import SimRobot
from hopper_ros.sim.runner import RESYNC_AFTER
from hopper_ros.sim.stance import StanceTorque

from hopper_ros.control.deadbeat import DeadbeatController, StrideDecision
from hopper_ros.control.stride_policy import StridePolicy, StrideSettings

_CHANNELS = iter(range(1 << 30))


@dataclass
class GraphRun:
    decisions: list[StrideDecision] = field(default_factory=list)
    apexes: list[tuple[float, float, float]] = field(default_factory=list)       # (time, height, speed) detected
    true_apexes: list[tuple[float, float, float]] = field(default_factory=list)  # from the simulator
    fell: bool = False
    stances: StanceTorque = field(default_factory=StanceTorque)


class GraphLockstep:
    """Simulated robot + sensing + controller + motor driver, stepped together."""

    def __init__(self, sim_config, hardware: HardwareConfig, controller: DeadbeatController,
                 driver_settings: DriverSettings | None = None, stride_settings: StrideSettings | None = None,
                 host_delay: Callable[[float], float] = lambda t: 0.0,
                 event_delay: Callable[[float], float] = lambda t: 0.0) -> None:
        self.host_time = 0.0          # [s] the graph's clock (the nodes' host clock)
        self.event_delay = event_delay   # [s] of an event's time: it reaches the controller this much later
        self._events_in_transit: list[tuple[float, object]] = []   #   (its executor starved; the repeats on time)
        channel = f"graph_lockstep_{next(_CHANNELS)}"
        self._drive_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self._master_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.robot = SimRobot(sim_config, hardware, drive=Epos2Emulator(self._drive_bus, hardware))
        # one SYNC per period of the robot, as the demo's launch files give the driver (sync_period: period): a
        # driver that took its SYNC period for 1 ms at 500 Hz averaged its ramp over half the period it is held
        settings = dataclasses.replace(driver_settings or DriverSettings(), sync_period=self.robot.period)
        self.driver = MotorDriver(self._master_bus, hardware, settings, clock=self._now)
        self.sensing = SensingPipeline.from_files(hardware=hardware)
        self.controller = controller
        self.policy = StridePolicy(controller, stride_settings or StrideSettings())
        self.host_delay = host_delay
        self._catching_up = False
        self._behind_base = 0.0       # [s] host minus robot time once the world stood still (not running behind)

    def _now(self) -> float:
        return self.host_time

    def close(self) -> None:
        self._drive_bus.shutdown()
        self._master_bus.shutdown()

    @property
    def setpoint(self) -> tuple[float, float] | None:
        return self.policy.setpoint

    def set_setpoint(self, height: float, speed: float) -> None:
        self.policy.on_setpoint(height, speed)

    def step(self, run: GraphRun) -> None:
        sample = self.robot.step(self._catching_up)
        run.stances.add(sample, self.robot.current_mode)
        for event in sample.events:
            if event.kind == "apex":
                run.true_apexes.append((event.t, event.z, event.ydot))
            elif event.kind == "fall":
                run.fell = True
        period = self.robot.period
        arrival = max(self.host_time, sample.truth.t + self.host_delay(sample.truth.t))
        gap = arrival - self.host_time
        # the robot runs behind when its samples come in a burst, or more than a period after their time (sim/runner.py's
        # `late > period`): its drive then takes one SYNC period of frames a step, not the frames sent for its future
        behind = arrival - sample.truth.t - self._behind_base
        self._catching_up = gap < 0.5 * period or behind > period
        if gap > 1.5 * period:
            # the simulated robot's process stalled: the graph runs on without samples, the controller
            # repeating its command, the driver sending SYNC to a drive that does not answer
            while arrival - self.host_time > 1.5 * period:
                self.host_time += period
                self._command()
                self._cycle()
            if gap > RESYNC_AFTER:                       # beyond it the world stood still (sim/runner.py):
                self.robot.drive.discard_syncs()   #   the SYNCs sent meanwhile are never answered
                self._behind_base = arrival - sample.truth.t   #   and it goes on from then, behind no more
            else:                                        # a shorter stall is caught up, a SYNC period a step
                self._catching_up = True
        self.host_time = arrival
        anchors = self.sensing.estimator.clock.anchors
        output = self.sensing.process(packet_format.encode(sample.packet), self.host_time)
        if self.sensing.estimator.clock.anchors != anchors:     # the estimator node's clock_offset topic
            self.policy.on_clock(self.sensing.estimator.clock.offset)
        self._events_in_transit += [(self.host_time + self.event_delay(event.time), event) for event in output.events]
        while self._events_in_transit and self._events_in_transit[0][0] <= self.host_time:
            self._on_event(self._events_in_transit.pop(0)[1], run)
        self._command()                          # the node's repeats: a thread of their own, every period here
        self._cycle(sync=gap >= 0.5 * period)    # the driver's SYNC period runs on the host clock: none in a burst

    def _command(self) -> None:
        now = self.host_time
        command = self.policy.command(now)
        if self.policy.due(command, now):
            self.driver.command(command.mode, command.setpoint, command.duration, now - command.time,
                                command.clock_offset)
        self.policy.drain_events()

    def _cycle(self, sync: bool = True) -> None:
        if sync:
            self.driver.cycle()
        while (frame := self._master_bus.recv(timeout=0.0)) is not None:
            self.driver.handle(frame)
        self.policy.on_drive_silence(self.driver.silent, self.driver.frozen_so_far())   # the driver's diagnostics
        level, message = self.driver.health()
        if level == ERROR:
            self.policy.on_drive_fault(message)

    def _on_event(self, event, run: GraphRun) -> None:
        self.policy.on_sensing(self.host_time)
        state = event.state
        self.policy.on_clock(state.stamp - state.mcu_time)
        if event.kind is EventType.APEX:
            run.apexes.append((event.time, state.z, state.y_dot))
            decision = self.policy.on_apex(state.z, state.y_dot, event.stride_index)
            if decision is not None:
                run.decisions.append(decision)
        elif event.kind is EventType.PRE_TOUCHDOWN:
            self.policy.on_pre_touchdown(event.time, state.z, state.z_dot, state.leg_angle, state.leg_angle_rate)
        elif event.kind is EventType.TOUCHDOWN:
            self.policy.on_touchdown(event.time)
        elif event.kind is EventType.LIFTOFF:
            self.policy.on_liftoff(state.leg_angle)

    def run(self, setpoints: Iterable[tuple[float, float]], settle_time: float = 0.5,
            max_time: float = 600.0) -> GraphRun:
        """Hold the robot until the drive is enabled, throw it, then one setpoint per detected apex."""
        setpoints = list(setpoints)
        run = GraphRun()
        self.set_setpoint(*setpoints[0])
        height, speed = setpoints[0]
        self.robot.throw(height, speed, self.controller.neutral_angle(speed), lead_time=0.05, hold=True)
        while self.robot.t < settle_time:
            self.step(run)
        self.robot.plant.release()
        while len(run.apexes) <= len(setpoints) and not run.fell and self.robot.t < max_time:
            index = min(len(run.apexes), len(setpoints) - 1)
            if setpoints[index] != self.setpoint:
                self.set_setpoint(*setpoints[index])
            self.step(run)
        return run

