"""The simulated robot run as the robot runs: its own thread steps the physics once per period
(on the wall clock in `realtime` mode, as fast as it goes in `lockstep`; a stall of the process of more
than RESYNC_AFTER freezes the simulated world for the SYNC periods that came meanwhile, its drive answering
none of them, as the driver expects; a shorter one is caught up), sends the microcontroller's UDP packet of
each period at its end to the encoder bridge on loopback and hands every period's sample to
the caller (the sim_robot node publishes its force plate, truth and events). The emulated EPOS2
sits on the CAN transport the `can` setting names, the motor driver's own selection
(canbus.driver.bus). No ROS import."""

from __future__ import annotations

import dataclasses
import socket
import threading
import time
from typing import Callable

from hopper_ros.canbus.driver.bus import open_drive_side, sim_transport
from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import HardwareConfig

from .experiment import ExperimentSeries
from .robot import SimRobot, SimSample

MODES = ("realtime", "lockstep")
RESYNC_AFTER = 0.02        # [s] further behind than this, real-time mode does not catch up: the time missed is
                           #   skipped, the robot's world was frozen, and the drive answers none of the SYNCs
                           #   that came meanwhile (the motor driver counts them as the time the robot stood
                           #   still and holds its stance ramp by it). Less far behind, the periods run late, one
                           #   SYNC period of the drive's frames each: the robot feels the driver's ramp as sent
                           #   (issue 29: a stall of 2 periods froze the world, and the driver could not tell a
                           #   frozen robot from answers late by as much, which held ramps of a robot that ran on)


def open_drive(can_setting: str, hardware: HardwareConfig, port: int | None):
    """The emulated EPOS2 on the transport `can_setting` names (`hub`, `virtual:CHANNEL`, `none`);
    returns (drive, closer, hub or None), (None, None, None) for none."""
    transport = sim_transport(can_setting, hardware.can, port)
    if transport is None:
        return None, None, None
    from hopper_ros.canbus.epos2_emulator import Epos2Emulator

    bus, close, hub = open_drive_side(transport)
    return Epos2Emulator(bus, hardware), close, hub


class SimRunner:
    """SimRobot with its drive, packet stream and pacing. `on_sample(sample)` is called from the
    stepping thread every period; `on_done()` once `duration` of simulated time has run;
    `on_failure(exc)` if the stepping thread raised: it has ended, the robot stands still, and the
    caller must end too (a process whose robot died silently kept its node alive: issue 29)."""

    def __init__(self, config, hardware: HardwareConfig, *, mode: str = "realtime", can: str = "hub",
                 can_port: int | None = None, udp_host: str = "127.0.0.1", udp_port: int | None = None,
                 duration: float = 0.0, experiments: bool = False, throw_lead: float = 0.05,
                 on_sample: Callable[[SimSample], None] = lambda sample: None,
                 on_done: Callable[[], None] = lambda: None,
                 on_failure: Callable[[BaseException], None] = lambda exc: None):
        if mode not in MODES:
            raise ValueError(f"mode must be realtime or lockstep, got {mode!r}")
        if udp_host not in ("127.0.0.1", "localhost"):
            raise ValueError(f"udp_host {udp_host!r}: the simulated robot only sends on loopback (127.0.0.1)")
        if experiments and can != "none":
            raise ValueError("experiments:=true runs the hip itself: it needs can:=none (no drive on a bus)")
        self.mode, self.duration, self.throw_lead = mode, duration, throw_lead
        self._on_sample, self._on_done, self._on_failure = on_sample, on_done, on_failure
        self.drive, self._close_drive, self.hub = open_drive(can, hardware, can_port)
        self.robot = SimRobot(config, hardware, drive=self.drive)
        self.series = ExperimentSeries(self.robot, seed=config.seed) if experiments else None
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._udp.bind(("127.0.0.1", 0))            # a sender on loopback only, not on 0.0.0.0
        port = udp_port if udp_port is not None else hardware.microcontroller.port
        self.udp_address = ("127.0.0.1", int(port))
        self.behind = 0.0        # [s] how far behind its clock the last period ran (real-time mode)
        self.last_freeze = (0.0, 0.0)   # [s] (the robot's time, how long its world stood still) of the latest freeze
        self._period_start = 0.0        # [s] the present period's start on the wall clock (real-time mode)
        self.counters = {"periods": 0, "deadline_misses": 0, "resyncs": 0, "udp_errors": 0, "falls": 0, "strides": 0,
                         "throws": 0}          # falls, strides: counted by the caller, from the samples' events
        self._lock = threading.Lock()
        self._pending_throw = None
        self._stop = threading.Event()
        self._wall_start = time.monotonic()
        self._thread = threading.Thread(target=self._run_reporting, name="sim-robot", daemon=True)

    def start(self) -> None:
        self._wall_start = time.monotonic()
        self._thread.start()

    def throw(self, apex_height: float, forward_speed: float, leg_angle: float, y: float = 0.0) -> None:
        """Throw the robot to a new apex at the next period (any thread)."""
        with self._lock:
            self._pending_throw = (apex_height, forward_speed, leg_angle, y)

    def realtime_factor(self) -> float:
        wall = time.monotonic() - self._wall_start
        return self.robot.t / wall if wall > 0 else 0.0

    def all_counters(self) -> dict[str, int]:
        """Ours, the emulated drive's (drive_*) and the CAN hub's (hub_*: clients dropped, garbage, ...)."""
        counters = dict(self.counters)
        if self.drive is not None:
            counters.update({f"drive_{k}": v for k, v in dataclasses.asdict(self.drive.counters).items()})
        if self.hub is not None:
            counters.update({f"hub_{k}": v for k, v in dataclasses.asdict(self.hub.counters).items()})
        return counters

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self._udp.close()
        if self._close_drive is not None:
            self._close_drive()

    def _run_reporting(self) -> None:
        try:
            self._run()
        except Exception as exc:  # noqa: BLE001 - the caller decides; the thread has ended either way
            self._on_failure(exc)

    def _wait_for_substep(self, offset: float) -> None:
        """Wait until `offset` into the present period, then hand the drive what reached it."""
        pause = self._period_start + offset - time.monotonic()
        if pause > 0.0:
            time.sleep(pause)
        if self.hub is not None:
            self.hub.read_pending()

    def _publish(self, sample: SimSample) -> None:
        try:
            self._udp.sendto(packet_format.encode(sample.packet), self.udp_address)
        except OSError:
            self.counters["udp_errors"] += 1
        self._on_sample(sample)

    def _run(self) -> None:
        """One period a loop. In real-time mode a period is computed at its start, with the drive's settings
        received until then, and its packet (the state at its end) goes out at its end, when the next one
        begins, as a microcontroller samples: a setting then acts on the robot from the period after the one
        it came in, never before it was sent; and before each of its drive's loop periods after the first (500 Hz:
        the second 1 ms) the runner waits for its instant and hands the drive what reached it by then. (Sent at
        once, the packets ran a period ahead of the robot's time on the host: the settings acted up to a period
        before they were sent, a stance ramp's first setting on the leg in the flight; bench_demo_load at 500 Hz,
        up to 0.7 cm of apex, docs/sim.md.)"""
        period = self.robot.period
        deadline = time.monotonic()
        realtime = self.mode == "realtime"
        pending: SimSample | None = None
        while not self._stop.is_set():
            if self.duration and self.robot.t >= self.duration - 1e-9:
                if pending is not None:
                    self._publish(pending)
                self._on_done()
                return
            if self.series is not None and (self.robot.experiment is None or self.robot.experiment.done):
                self.series.start_next()
            with self._lock:
                throw, self._pending_throw = self._pending_throw, None
            if throw is not None:
                self.robot.throw(*throw, lead_time=self.throw_lead)
                self.counters["throws"] += 1
            catching_up = False
            if realtime:
                late = time.monotonic() - deadline
                if late > RESYNC_AFTER:                    # the time missed is skipped: the robot was frozen
                    self.counters["resyncs"] += 1
                    if self.hub is not None:
                        self.hub.read_pending()            # what the master sent meanwhile, at the drive now
                    frozen = late
                    if self.drive is not None:
                        # the SYNC of the period it stopped in is answered (the drive's SYNC period is the robot's,
                        # demo/*.yaml); the world stands still for the SYNCs it never answers, whole periods, so that
                        # the driver's count of them is the time it stood still (counted from a continuous freeze: off
                        # by up to 4 ms, docs/sim.md), and what is left over is caught up. When fewer came than that
                        # leaves less than RESYNC_AFTER to catch up (the master stalled too, or is not up yet) it stands
                        # still for all of it, as before (caught up, the robot fell: a starved graph that ran late
                        # through a stance)
                        unanswered = self.drive.discard_syncs(1) * period
                        frozen = unanswered if late - unanswered < RESYNC_AFTER else late
                    deadline += frozen
                    self.last_freeze = (self.robot.t, frozen)
                    late = time.monotonic() - deadline
                catching_up = late > period
                self.behind = late
            if pending is not None:                # the period that ends now: its packet and sample
                self._publish(pending)
            if self.hub is not None:               # every frame that has reached the drive by now, whichever of
                self.hub.read_pending()            #   this process's threads runs first (the hub's could wait a step)
            self._period_start = deadline
            pending = self.robot.step(catching_up, self._wait_for_substep if realtime else None)
            self.robot.plant.events.clear()      # the sample holds them: the plant's history grew without end
            self.counters["periods"] += 1        #   (0.4 kB an event, 40k an hour: the soak's memory growth)
            if not realtime:
                self._publish(pending)
                pending = None
            if realtime:
                deadline += period
                wait = deadline - time.monotonic()
                if wait > 0.0:
                    time.sleep(wait)
                else:
                    self.counters["deadline_misses"] += 1
