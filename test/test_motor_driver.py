"""The motor driver (hopper_ros.canbus.driver) against the emulated EPOS2 on a python-can `virtual`
bus, with the independent `canopen` library on the same bus reading the drive's configuration
back by SDO and decoding every PDO, EMCY and heartbeat.

The rig runs in simulated time, 1 ms per step: the drive's cycle, the driver's cycle, then frames
are exchanged until the bus is quiet; canopen gets every frame synchronously (Network.notify), so
what it decoded can be tied to the step it happened in.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
import time
from functools import partial

import can
import canopen
import numpy as np
import pytest

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_emulator import Epos2Emulator
from hopper_ros.canbus.epos2_objects import Command, NmtState, State
from hopper_ros.canbus.driver import (
    ERROR,
    MODE_CURRENT,
    MODE_DISABLED,
    MODE_POSITION,
    MODE_RAMP,
    WARN,
    DriverSettings,
    MotorDriver,
    Phase,
    load_motor_driver,
    open_bus,
)
from hopper_ros.hardware.config import CanBus, load_hardware
from test_motor_driver_master import canopen_dictionary

HW = load_hardware()
NODE = HW.drive.node_id
K_T, GEAR = HW.motor.torque_constant, HW.motor.gear_ratio
COUNTS_PER_LEG_TURN = 500 * 4 * 26
SETTINGS = DriverSettings()             # the defaults: 1 ms SYNC, 10 ms command timeout
_channels = itertools.count()


class ManualClock:
    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


class Rig:
    """Driver + emulated EPOS2 + canopen observer on one virtual channel, stepped in simulated time."""

    def __init__(self, settings: DriverSettings = SETTINGS, before_start=None):
        channel = f"motor_driver_test_{next(_channels)}"
        self.clock = ManualClock()
        self.driver_bus = can.Bus(interface="virtual", channel=channel)
        self.drive_bus = can.Bus(interface="virtual", channel=channel)
        self.spy_bus = can.Bus(interface="virtual", channel=channel)
        self.drive = Epos2Emulator(self.drive_bus, HW)
        if before_start:
            before_start(self)
        self.driver = MotorDriver(self.driver_bus, HW, settings, clock=self.clock)
        self.network = canopen.Network(self.spy_bus)        # no notifier: the rig feeds it
        self.remote = canopen.RemoteNode(NODE, canopen_dictionary(NODE))
        self.network.add_node(self.remote)
        self.counts, self.rpm = 0, 0.0
        self.drive_alive = self.driver_alive = True
        self.frames: list[tuple[float, int, bytes]] = []    # every frame on the bus: (time, COB-ID, data)
        self._stamp: float | None = None                    # time of a frame replayed to canopen
        self.rpdos: list[tuple[float, int, tuple]] = []     # (time, RPDO number, values decoded by canopen)
        self.states: list[State] = []                       # the drive's state after each step
        self.step_count = 0

    def close(self) -> None:
        for bus in (self.driver_bus, self.drive_bus, self.spy_bus):
            bus.shutdown()

    # -------------------------------------------------------------- stepping
    def step(self, n: int = 1, command: tuple[int, float] | None = None) -> None:
        for _ in range(n):
            self.clock.t += 0.001
            self.step_count += 1
            if command is not None and self.driver_alive:
                self.driver.command(*command)
            if self.drive_alive:
                self.drive.poll(self.clock.t)
                self.drive.control(self.clock.t, self.counts, self.rpm, self.drive.demand)
            if self.driver_alive:
                self.driver.cycle()
            self._settle()
            self.states.append(self.drive.state)

    def _settle(self) -> None:
        for _ in range(100):
            if self.drive_alive:
                self.drive.poll(self.clock.t)
            moved = False
            while True:
                try:
                    frame = self.driver_bus.recv(timeout=0)
                except can.CanError as exc:
                    self.driver.bus_error(str(exc))
                    break
                if frame is None:
                    break
                moved = True
                if self.driver_alive:
                    self.driver.handle(frame)
            if not moved:
                break
        while (frame := self.spy_bus.recv(timeout=0)) is not None:
            self.frames.append((self.clock.t, frame.arbitration_id, bytes(frame.data)))
            try:
                self.network.notify(frame.arbitration_id, frame.data, self.clock.t)
            except Exception:  # noqa: BLE001 - canopen may choke on the malformed frames of a test
                pass

    def until(self, condition, limit: int = 2000, command=None) -> int:
        """Step until condition() holds; the number of steps taken."""
        for taken in range(limit):
            if condition():
                return taken
            self.step(command=command)
        raise AssertionError(f"condition not reached in {limit} steps; driver {self.driver.phase}, "
                             f"drive {self.drive.state}, events {self.driver.drain_events()[-5:]}")

    # -------------------------------------------------------------- canopen observer
    def read_pdo_configuration(self) -> None:
        """canopen reads the PDO configuration from the drive by SDO (in a thread; we keep stepping)."""
        errors = []

        def read():
            try:
                self.remote.rpdo.read()
                self.remote.tpdo.read()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)

        reader = threading.Thread(target=read)
        reader.start()
        end = time.monotonic() + 20.0
        while reader.is_alive():
            self.step()
            time.sleep(0.0002)
            assert time.monotonic() < end, "canopen did not finish reading the PDO configuration"
        assert not errors, errors
        for number in (1, 2):
            pdo_map = self.remote.rpdo[number]
            pdo_map.add_callback(lambda pdo, number=number: self.rpdos.append(
                (self._stamp if self._stamp is not None else self.clock.t, number, tuple(v.raw for v in pdo))))
            for self._stamp, cob, data in self.frames:                 # what went out before canopen knew
                if cob == pdo_map.cob_id:
                    pdo_map.on_message(cob, data, self._stamp)
            self._stamp = None
        self.rpdos.sort(key=lambda row: row[0])

    def controlwords(self, since: float = -math.inf) -> list[int]:
        return [values[0] for t, _, values in self.rpdos if t > since]

    def start(self) -> "Rig":
        self.until(lambda: self.driver.phase is Phase.RUNNING, limit=50)
        self.read_pdo_configuration()
        return self

    def enable(self, torque: float = 0.5) -> None:
        self.until(lambda: self.drive.state is State.OPERATION_ENABLED, limit=300, command=(MODE_CURRENT, torque))


def dedup(values):
    return [v for i, v in enumerate(values) if i == 0 or v != values[i - 1]]


@pytest.fixture
def rig():
    rigs = []

    def make(**kwargs) -> Rig:
        rigs.append(Rig(**kwargs))
        return rigs[-1]

    yield make
    for r in rigs:
        r.close()


def _milliamps(torque: float) -> int:
    return round(torque / (K_T * GEAR) * 1000.0)


# ------------------------------------------------------------------------------------------------


def test_startup_configures_the_drive_as_canopen_reads_it_back(rig):
    r = rig()
    steps = r.until(lambda: r.driver.phase is Phase.RUNNING, limit=50)
    assert steps <= 3                                                   # one SDO after the other, no waiting
    drive = r.drive
    assert drive.nmt_state == NmtState.OPERATIONAL
    assert drive.value(eo.PRODUCER_HEARTBEAT_TIME) == 100
    assert drive.value(eo.CONSUMER_HEARTBEAT_TIME, 1) == (127 << 16) | 200
    assert drive.value(eo.MOTOR_DATA, 1) == 10000 and drive.value(eo.MOTOR_DATA, 2) == 20000
    assert [drive.value(eo.POSITION_CONTROL_PARAMETERS, s) for s in (1, 2, 3)] == [537, 2179, 705]
    assert drive.value(eo.MODES_OF_OPERATION) == -3
    r.read_pdo_configuration()
    rpdo, tpdo = r.remote.rpdo, r.remote.tpdo
    layout = lambda pdo: [(v.index, v.subindex, v.length) for v in pdo]  # noqa: E731
    assert rpdo[1].enabled and rpdo[1].cob_id == 0x200 + NODE and rpdo[1].trans_type == 255
    assert layout(rpdo[1]) == [(0x6040, 0, 16), (0x6060, 0, 8), (0x2030, 0, 16)]
    assert rpdo[2].enabled and rpdo[2].cob_id == 0x300 + NODE and rpdo[2].trans_type == 255
    assert layout(rpdo[2]) == [(0x6040, 0, 16), (0x6060, 0, 8), (0x2062, 0, 32)]
    assert tpdo[1].enabled and tpdo[1].cob_id == 0x180 + NODE and tpdo[1].trans_type == 1
    assert layout(tpdo[1]) == [(0x6041, 0, 16), (0x6064, 0, 32), (0x6078, 0, 16)]
    assert tpdo[2].enabled and tpdo[2].cob_id == 0x280 + NODE and tpdo[2].trans_type == 1
    assert layout(tpdo[2]) == [(0x606C, 0, 32), (0x6061, 0, 8), (0x603F, 0, 16)]
    assert not any(p.enabled for p in (rpdo[3], rpdo[4], tpdo[3], tpdo[4]))
    r.step(150)                                                         # a drive heartbeat (100 ms) passes
    assert r.remote.nmt.state == "OPERATIONAL" and r.driver.status.heartbeat_ok
    assert r.driver.counters["sync_sent"] >= 150 and r.driver.counters["tpdo_missed"] == 0
    assert r.driver.counters["malformed_frames"] == 0 and r.driver.counters["sdo_aborts"] == 0
    assert r.drive.state is State.SWITCH_ON_DISABLED                    # no command yet: power stage off
    assert set(r.controlwords()) == {Command.DISABLE_VOLTAGE}


def test_state_machine_resets_a_startup_fault_then_enables_on_command(rig):
    r = rig(before_start=lambda rig: rig.drive.inject_fault(eo.ERROR_OVER_CURRENT, rig.clock.t))
    assert r.drive.state is State.FAULT
    r.start()
    r.until(lambda: r.drive.state is State.SWITCH_ON_DISABLED, limit=50)
    status = r.driver.status
    assert (status.fault_code, status.fault_text) == (0x2310, "Over current error")   # read at start-up (0x603F)
    assert r.driver.counters["fault_resets"] == 1
    r.step(150)                                                         # stays off without a command
    assert r.drive.state is State.SWITCH_ON_DISABLED
    r.enable()
    r.step(5, command=(MODE_CURRENT, 0.5))
    assert dedup(r.controlwords()) == [Command.DISABLE_VOLTAGE, Command.FAULT_RESET, Command.DISABLE_VOLTAGE,
                                       Command.SHUTDOWN, Command.SWITCH_ON_AND_ENABLE]
    assert dedup(r.states) == [State.FAULT, State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON,
                               State.OPERATION_ENABLED]
    assert r.driver.status.state is State.OPERATION_ENABLED and r.driver.status.commanded_mode == MODE_CURRENT
    assert r.driver.health() == (0, "")


def test_pdo_contents_and_scaling_with_the_current_limit(rig):
    r = rig().start()
    r.enable(torque=1.0)
    r.step(3, command=(MODE_CURRENT, 1.0))
    t, number, (controlword, mode, milliamps) = r.rpdos[-1]
    assert (number, controlword, mode, milliamps) == (1, 0x000F, -3, _milliamps(1.0)) and milliamps == 1595
    assert r.drive.demand == pytest.approx(1.595)
    r.step(2, command=(MODE_CURRENT, -30.0))                             # beyond 20 A x k_t x 26 = 12.5 N m
    assert r.rpdos[-1][2] == (0x000F, -3, -20000) and r.drive.demand == pytest.approx(-20.0)
    assert r.driver.counters["current_clamped"] == 2
    r.step(2, command=(MODE_CURRENT, 12.0))
    assert r.rpdos[-1][2] == (0x000F, -3, _milliamps(12.0))

    r.step(3, command=(MODE_POSITION, 0.1))
    assert r.rpdos[-1][1:] == (2, (0x000F, -1, round(0.1 * COUNTS_PER_LEG_TURN / (2 * math.pi))))
    assert r.rpdos[-1][2][2] == 828 and r.drive.operation_mode == -1
    assert r.drive.value(eo.POSITION_MODE_SETTING_VALUE) == 828

    # feedback: canopen's decoding of the TPDOs and the driver's SI values agree
    r.counts, r.rpm = COUNTS_PER_LEG_TURN // 4, 1000.0
    r.step(3, command=(MODE_POSITION, 0.1))
    tpdo1, tpdo2 = r.remote.tpdo[1], r.remote.tpdo[2]
    status = r.driver.status
    assert tpdo1[1].raw == COUNTS_PER_LEG_TURN // 4 and status.position == pytest.approx(math.pi / 2, rel=1e-12)
    assert tpdo2[0].raw == 1000 and status.velocity == pytest.approx(1000 * 2 * math.pi / 60 / GEAR, rel=1e-12)
    assert tpdo2[1].raw == -1 and status.operation_mode == -1 and status.commanded_mode == MODE_POSITION
    assert tpdo1[2].raw == round(r.drive.demand * 1000)
    assert status.current == pytest.approx(tpdo1[2].raw / 1000.0)
    assert status.torque == pytest.approx(status.current * K_T * GEAR)
    assert tpdo1[0].raw == status.statusword == eo.STATUSWORD_OF_STATE[State.OPERATION_ENABLED]


def _run_ramp(r, tau_0, duration, stamp, steps):
    """Keep-alive repeats of a MODE_RAMP command stamped `stamp` (the age grows); (time, mA) per step."""
    seen = []
    for _ in range(steps):
        r.step(1, command=(MODE_RAMP, tau_0, duration, r.clock.t + 0.001 - stamp))
        seen.append((r.clock.t, r.rpdos[-1][2][2]))
    return seen


def _ramp_milliamps(tau_0, duration, since_start):
    """The ramp (2.32) averaged over the SYNC period the drive holds the setting (midpoint samples);
    `since_start` is simulated time from the ramp's start, not a wall clock."""
    period = SETTINGS.sync_period
    times = since_start + (np.arange(2000) + 0.5) * period / 2000
    return _milliamps(float(np.mean(np.where((times >= 0.0) & (times < duration), -tau_0 * (1.0 - times / duration), 0.0))))


def _ramp_on_clock(r, tau_0, duration, stamp, clock_offset, steps):
    """`steps` keep-alive repeats of a MODE_RAMP command stamped `stamp` on the sensing clock `clock_offset` names."""
    for _ in range(steps):
        r.step(1, command=(MODE_RAMP, tau_0, duration, r.clock.t + 0.001 - stamp, clock_offset))


def _stand_still(r, ramp, stamp, stood):
    """The robot stands still `stood` s (its drive answers no SYNC) while the ramp stamped `stamp` goes on; then it
    wakes, the SYNCs it never saw discarded."""
    r.drive_alive = False
    ramp(stamp, 0.0, round(stood / SETTINGS.sync_period))
    r.drive.discard_syncs()
    r.drive_alive = True


def _given(rpdos, until):
    """[mA s] What the drive gave from `rpdos` (time, number, values), each setting held until the next or `until`."""
    times = [t for t, _, _ in rpdos] + [until]
    return sum(values[2] * (after - t) for (t, _, values), after in zip(rpdos, times[1:]))


def test_ramp_mode_runs_the_stance_ramp_in_the_driver_from_its_start(rig):
    """The ramp runs from its stamp; a command that came 4 ms after it gives the 4 ms it skipped as soon as the
    current limit allows (skipped, each ms moved the apex ~4 mm): the stance gets the ramp's whole impulse."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, age = 6.0, 0.05, 0.004               # the touchdown was 4 ms before the command arrived
    sent_before = len(r.rpdos)
    r.driver.command(MODE_RAMP, tau_0, duration, age)
    start = r.clock.t - age
    seen = _run_ramp(r, tau_0, duration, start, 60)       # repeats of the same ramp (keep-alive) keep its start
    limit = round(HW.drive.current_limit * 1000) - 1
    paid = [m for t, m in seen if m != pytest.approx(_ramp_milliamps(tau_0, duration, t - start), abs=1)]
    assert paid and all(abs(m) >= limit - 1 for m in paid[:-1])        # at the limit until the skipped part is given
    assert all(m == pytest.approx(_ramp_milliamps(tau_0, duration, t - start), abs=1) for t, m in seen[len(paid):])
    settings = r.rpdos[sent_before:]                       # each held by the drive until the next
    given = _given(settings, r.clock.t)                    # the last, held on, is 0
    # [mA s] the whole impulse, but for the command's own RPDO, which this drive takes at its next poll
    assert given == pytest.approx(_milliamps(-tau_0) * duration / 2, abs=abs(_milliamps(tau_0)) * SETTINGS.sync_period)
    assert seen[-1][1] == 0 and r.driver.counters["commands_rejected"] == 0
    assert not r.driver.command(MODE_RAMP, tau_0, 0.0)   # a ramp needs a positive duration


def test_a_ramp_scheduled_ahead_waits_for_its_stamp_and_moves_to_a_new_one(rig):
    """The controller sends the ramp at pre-touchdown, stamped with the predicted touchdown: zero current
    until then; the measured touchdown (a new stamp, 2 ms later) moves the running ramp."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration = 6.0, 0.05
    predicted = r.clock.t + 0.008
    early = _run_ramp(r, tau_0, duration, predicted, 12)
    for t, milliamps in early:
        assert milliamps == pytest.approx(_ramp_milliamps(tau_0, duration, t - predicted), abs=1)
    assert early[0][1] == 0 and early[-1][1] != 0
    measured = predicted + 0.0025                       # between two SYNCs
    late = _run_ramp(r, tau_0, duration, measured, 60)
    for t, milliamps in late:
        assert milliamps == pytest.approx(_ramp_milliamps(tau_0, duration, t - measured), abs=1)
    assert r.driver.counters["commands_rejected"] == 0


@pytest.mark.parametrize("stall", [0, 2, 4, 6])
@pytest.mark.parametrize("touchdown_after", [0.0035, 0.0055, 0.0065])
def test_a_setting_held_while_the_drivers_own_cycle_stalled_is_given_back(rig, stall, touchdown_after):
    """The drive holds each current until the next RPDO. The driver's own cycle stalled at a touchdown (loaded,
    normal scheduling: the touchdown's first setting, the ramp's share of the period in which it began, held
    6 ms, 1.4 cm off the next apex): what the hold withheld is given back as the current limit allows, so
    the stance gets the ramp's whole impulse whatever the stall, to within what the drive takes of it at its
    next poll."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration = 9.0, 0.05
    touchdown = r.clock.t + touchdown_after             # between two SYNCs, before the stall or in it
    sent_before = len(r.rpdos)
    _run_ramp(r, tau_0, duration, touchdown, 5)
    r.driver_alive = False                              # the driver's process starved: no cycle, no command
    r.step(stall)
    r.driver_alive = True
    _run_ramp(r, tau_0, duration, touchdown, 80)
    ramp = _milliamps(-tau_0) * duration / 2
    given = _given(r.rpdos[sent_before:], r.clock.t)
    assert given == pytest.approx(ramp, abs=abs(_milliamps(tau_0)) * SETTINGS.sync_period * 0.6)
    assert r.driver.counters["commands_rejected"] == 0


def test_what_a_late_ramp_owes_is_given_whole_when_the_drivers_cycle_runs_its_missed_periods_at_once(rig):
    """After a stall of its own the driver's cycle runs the periods it missed at once, each setting held a fraction
    of a period: the impulse a late ramp owes, booked a period's worth with each, was spent by them and not given
    (a loaded 500 Hz run: 9 of 9 mN m s owed gone in 0.4 ms). A SYNC sooner than a period after the last gives back
    what that one booked and did not hold."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, age = 9.0, 0.05, 0.004
    sent_before = len(r.rpdos)
    r.driver.command(MODE_RAMP, tau_0, duration, age)
    start = r.clock.t - age
    for _ in range(3):                                  # the periods it missed, at once
        r.driver.cycle()
        r._settle()
    _run_ramp(r, tau_0, duration, start, 70)
    given = _given(r.rpdos[sent_before:], r.clock.t)
    assert given == pytest.approx(_milliamps(-tau_0) * duration / 2, abs=abs(_milliamps(tau_0)) * SETTINGS.sync_period * 0.2)


def test_a_ramp_that_reaches_the_driver_after_its_start_is_counted_and_said(rig):
    """A ramp whose start has passed when it arrives loses its first part (~4 mm of apex a ms): counted, its
    lateness kept, and said with its cause, so that a stride that misses its apex shows where its torque went. A
    ramp scheduled ahead and on time is not."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration = 6.0, 0.05
    predicted = r.clock.t + 0.010
    _run_ramp(r, tau_0, duration, predicted, 3)               # ahead: waiting for its stamp
    r.driver.drain_events()
    assert r.driver.counters["ramps_begun_late"] == 0
    measured = r.clock.t - 0.003                               # the touchdown came 3 ms before its prediction
    _run_ramp(r, tau_0, duration, measured, 2)
    assert r.driver.counters["ramps_begun_late"] == 1
    assert r.driver.ramp_late_max == pytest.approx(0.004, abs=1e-6)  # heard at the next step, 1 ms on
    said = [text for _, text in r.driver.drain_events() if "stance ramp began" in text]
    assert len(said) == 1 and "the touchdown came before its prediction" in said[0], said
    r.step(60, command=(MODE_POSITION, 0.0))
    r.driver.command(MODE_RAMP, 7.0, duration, 0.0045)         # a new ramp whose command came 4.5 ms late
    assert r.driver.counters["ramps_begun_late"] == 2
    assert r.driver.ramp_late_max == pytest.approx(0.0045, abs=1e-6)
    assert any("the command came after its touchdown" in text for _, text in r.driver.drain_events())
    on_time = r.clock.t + 0.008
    r.step(5, command=(MODE_POSITION, 0.0))
    _run_ramp(r, tau_0, duration, on_time + 0.005, 20)          # scheduled ahead, started at its stamp
    assert r.driver.counters["ramps_begun_late"] == 2


@pytest.mark.parametrize("phase", [0.0, 0.25e-3, 0.5e-3, 0.9e-3])
def test_the_ramp_gives_its_whole_impulse_wherever_the_touchdown_falls_between_two_syncs(rig, phase):
    """The drive holds each current for a SYNC period: the period the touchdown falls in gets the ramp's
    share of it, so the stance gets tau_0 t_f / 2 whatever the touchdown's phase (sampled at the SYNC, up
    to a period of tau_0 was lost: the onset moved by up to 1 ms, the apex by about 0.1 cm)."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration = 6.0, 0.05
    touchdown = r.clock.t + 0.004 + phase
    seen = _run_ramp(r, tau_0, duration, touchdown, 70)
    impulse = sum(milliamps for _, milliamps in seen) * SETTINGS.sync_period
    assert impulse == pytest.approx(_milliamps(-tau_0) * duration / 2, abs=len(seen) * SETTINGS.sync_period)


def test_a_touchdown_stamped_after_a_stand_still_starts_its_ramp_at_its_stamp(rig):
    """The robot stands still 100 ms (its drive answers none of the SYNCs: the simulated robot's process
    stopped) before a touchdown predicted on the sensing clock as it stood before. The touchdown measured
    after it is stamped on the clock re-anchored by the stand-still, and its command can come before the
    drive's first answer (its hub sends what it held first): the driver, which could not tell that stamp
    from one on the old clock, moved it by the whole stand-still, and that stance got no torque (bench
    round 4: 1.4 m/s lost). The command's clock_offset, stepped by the stand-still, tells it."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, stood = 6.0, 0.05, 0.1
    predicted = r.clock.t + 0.015
    ramp = partial(_ramp_on_clock, r, tau_0, duration)

    ramp(predicted, 0.0, 5)
    r.drive_alive = False                                  # the robot stands still
    ramp(predicted, 0.0, round(stood / SETTINGS.sync_period))
    r.drive.discard_syncs()
    measured = r.clock.t + 0.001                           # just after it, on the re-anchored clock
    ramp(measured, stood, 3)                               # heard before the drive's first answer
    r.drive_alive = True
    ramp(measured, stood, 60)
    for t, _, values in r.rpdos:
        if t > measured:
            assert values[2] == pytest.approx(_ramp_milliamps(tau_0, duration, t - measured), abs=1)
    assert r.driver.frozen_time >= stood - 2 * SETTINGS.sync_period     # the answers' count, moving nothing


def test_a_ramp_begun_where_a_stand_stills_count_put_it_and_restamped_earlier_owes_what_it_missed(rig):
    """The robot stands still across its predicted touchdown; the count of the SYNCs its drive never answered moves
    the ramp's start past the stand-still, and the ramp begins there. The touchdown measured on the re-anchored clock
    comes 3 ms before that start (the count ran over the stand-still and the world had run on since it woke): the
    ramp moved to it and its first 3 ms were never given (bench_demo_load, SCHED_FIFO at 1 kHz, a stall 2 ms before
    a touchdown: the torque on the leg 4 ms after it, the apex 0.79 cm high). What it owes from its new start, less
    what the drive was sent since, is given as the current limit allows: the stance gets the ramp's whole impulse."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, stood = 9.0, 0.06, 0.1
    predicted = r.clock.t + 0.005
    ramp = partial(_ramp_on_clock, r, tau_0, duration)

    ramp(predicted, 0.0, 4)
    _stand_still(r, ramp, predicted, stood)                # across the touchdown
    back = len(r.rpdos)
    ramp(predicted, 0.0, 4)
    counted = r.driver._ramp[2]
    assert counted < r.clock.t and r.rpdos[-1][2][2] != 0  # begun where the count put it
    measured = counted - 0.003
    ramp(measured, stood, 90)                              # the re-anchored clock: 3 ms before the counted start
    given = _given(r.rpdos[back:], r.clock.t)
    assert given == pytest.approx(_milliamps(-tau_0) * duration / 2, abs=abs(_milliamps(tau_0)) * SETTINGS.sync_period)
    assert any("the start the stand-still's count gave it" in text for _, text in r.driver.drain_events())


@pytest.mark.parametrize("steps_in, heard_after, early", [(20, 3, 0.0), (20, 0, 0.002), (4, 3, 0.003)])
def test_a_stand_still_in_mid_stance_owes_nothing_once_the_stamps_re_anchor(rig, steps_in, heard_after, early):
    """The robot stands still 17 ms into a stance: the ramp waits with it, and the touchdown's stamp on the clock
    re-anchored by the stand-still is its start moved by about as much, `early` before where the count of the
    stand-still put it. What the drive was sent before the stand-still is on the host's clock before that stamp:
    counted as not given, the ramp's first 17 ms were owed and paid again (the torque at the current limit after
    the stand-still; an attempt at the test above: every run of a stall-heavy bench 1.0-1.7 cm off). Whether the
    re-anchored stamps are heard after the drive's first answer or before it (its silence not yet over), the
    settings follow the ramp from its new stamp, and the stance gets its impulse once. So too where the stand-still
    came 1 ms into the stance and its count ran past the drive's first answer (`steps_in` 4): the robot woke to the
    ramp's setting and ran on it while it caught up its world (bench_demo_load at 500 Hz: owed again, 10 ms at the
    current limit, the apex 1.52 cm low)."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, stood = 9.0, 0.06, 0.1
    touchdown = r.clock.t + 0.003
    ramp = partial(_ramp_on_clock, r, tau_0, duration)

    first = len(r.rpdos)
    ramp(touchdown, 0.0, steps_in)
    stopped, stopped_at = len(r.rpdos), r.clock.t
    _stand_still(r, ramp, touchdown, stood)                # in mid stance
    back = len(r.rpdos)
    ramp(touchdown, 0.0, heard_after)
    anchored, restamped = len(r.rpdos), touchdown + stood - early
    ramp(restamped, stood, 60)                             # the touchdown on the re-anchored clock
    for t, _, values in r.rpdos[anchored:]:
        assert values[2] == pytest.approx(_ramp_milliamps(tau_0, duration, t - restamped), abs=1)
    if not early:
        given = _given(r.rpdos[first:stopped], stopped_at) + _given(r.rpdos[back:], r.clock.t)
        assert given == pytest.approx(_milliamps(-tau_0) * duration / 2,
                                      abs=abs(_milliamps(tau_0)) * SETTINGS.sync_period)


def test_a_sensing_clock_re_anchored_while_the_drive_answered_every_sync_moves_no_ramp(rig):
    """The sensing host, starved for 20-30 ms and catching up at less than twice the packets' pace, read them late
    long enough for its clock to re-anchor by 11 ms, while the robot ran on (its drive answered every SYNC). The
    touchdown measured on that clock moved the ramp 11 ms past the touchdown (bench_demo_load, normal scheduling:
    the torque reached the leg 12.1 ms late, the apex 1.65 cm off). The step is the host's: taken off the stamps,
    and off them no more once the clock comes back."""
    from hopper_ros.canbus.driver.stillness import STOOD_STILL_LATELY

    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, step = 6.0, 0.05, 0.011
    ramp = partial(_ramp_on_clock, r, tau_0, duration)

    r.step(round(STOOD_STILL_LATELY / SETTINGS.sync_period), command=(MODE_POSITION, 0.0))   # answering for a while
    predicted = r.clock.t + 0.005
    ramp(predicted, 0.0, 8)                              # running from its predicted touchdown
    touchdown = predicted + 0.001                        # measured 1 ms after it, heard 2 ms later,
    ramp(touchdown + step, step, 60)                     # stamped on the re-anchored clock
    seen = [(t, values[2]) for t, _, values in r.rpdos if t > r.clock.t - 0.058]
    for t, milliamps in seen:
        assert milliamps == pytest.approx(_ramp_milliamps(tau_0, duration, t - touchdown), abs=1)
    assert any("keeps the drive's time" in text for _, text in r.driver.drain_events())
    r.step(40, command=(MODE_POSITION, 0.0))
    later = r.clock.t + 0.006                           # the clock back on its mapping: stamps as they are
    r.rpdos.clear()
    ramp(later, 0.0, 40)
    for t, _, values in r.rpdos:
        if t > later + 0.001:
            assert values[2] == pytest.approx(_ramp_milliamps(tau_0, duration, t - later), abs=1)


def test_a_sensing_clock_re_anchored_after_the_drivers_own_cycle_stalled_is_followed(rig):
    """The driver's own process starved 48 ms while the simulated robot's world stood still as long (its runner
    starved past RESYNC_AFTER): the driver sent no SYNC meanwhile, so none went unanswered, and the answers after
    it looked like a drive that ran on. Taken for the host's lateness, the sensing clock's step of 48 ms was kept
    off every later stamp and each stance ramp began 48 ms before its touchdown (a loaded 500 Hz run at start-up:
    the robot fell in 5 strides). A stalled cycle watched no answers: the step is followed."""
    from hopper_ros.canbus.driver.stillness import STOOD_STILL_LATELY

    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, step = 6.0, 0.05, 0.048
    r.step(round(STOOD_STILL_LATELY / SETTINGS.sync_period), command=(MODE_POSITION, 0.0, 0.0, 0.0, 0.0))
    r.driver_alive = r.drive_alive = False               # both starved: no SYNC sent, the robot's world still
    r.step(round(step / 0.001))
    r.driver_alive = r.drive_alive = True
    r.step(5, command=(MODE_POSITION, 0.0, 0.0, 0.0, step))   # the sensing clock re-anchored by the stand-still
    stamp = r.clock.t + 0.010                            # a touchdown predicted on it
    r.rpdos.clear()
    for _ in range(40):
        r.step(1, command=(MODE_RAMP, tau_0, duration, r.clock.t + 0.001 - stamp, step))
    for t, _, values in r.rpdos:
        if t < stamp - 0.001:
            assert values[2] == 0, f"ramp current {values[2]} mA at {1e3 * (t - stamp):.0f} ms before its touchdown"
        elif t > stamp + 0.001:
            assert values[2] == pytest.approx(_ramp_milliamps(tau_0, duration, t - stamp), abs=1)
    assert not any("keeps the drive's time" in text for _, text in r.driver.drain_events())


def test_a_step_of_the_sensing_clock_not_taken_back_is_followed_after_stamp_shift_kept(rig):
    """A step later taken for the host's lateness is proved by the step back when the host catches up; one that
    never comes back was the robot's (a stand-still its drive's answers could not show). Kept for good, it put
    every later ramp that far ahead of its touchdown; past STAMP_SHIFT_KEPT the stamps are followed again."""
    from hopper_ros.canbus.driver.stillness import STAMP_SHIFT_KEPT, STOOD_STILL_LATELY

    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, step = 6.0, 0.05, 0.03
    r.step(round(STOOD_STILL_LATELY / SETTINGS.sync_period), command=(MODE_POSITION, 0.0, 0.0, 0.0, 0.0))
    r.step(5, command=(MODE_POSITION, 0.0, 0.0, 0.0, step))
    assert any("keeps the drive's time" in text for _, text in r.driver.drain_events())
    r.step(round(STAMP_SHIFT_KEPT / 0.001) + 5, command=(MODE_POSITION, 0.0, 0.0, 0.0, step))
    assert any("follows the stamps" in text for _, text in r.driver.drain_events())
    stamp = r.clock.t + 0.010
    r.rpdos.clear()
    for _ in range(40):
        r.step(1, command=(MODE_RAMP, tau_0, duration, r.clock.t + 0.001 - stamp, step))
    started = [t for t, _, values in r.rpdos if values[2] != 0]
    assert started and started[0] >= stamp - 0.001, "the ramp began before its touchdown"


def test_a_sensing_clock_re_anchored_before_the_drive_has_answered_for_long_is_followed(rig):
    """Where the drive's answers cannot tell (it has answered for less than STOOD_STILL_LATELY: the graph starting,
    the simulated robot stopped before its drive was enabled), a re-anchored clock is followed as before: taken
    for the host's lateness, a 98.5 ms stand-still at start-up left every later ramp 98.5 ms in the past (each given
    as the current limit allows; the robot fell in 3 of 5 loaded runs)."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration, step = 6.0, 0.05, 0.0985
    r.driver.command(MODE_POSITION, 0.0, clock_offset=0.0)      # the mapping as it stood
    began = r.clock.t
    stamp = began + step + 0.005                          # on the re-anchored clock: 5 ms ahead on this one too
    for _ in range(60):
        r.step(1, command=(MODE_RAMP, tau_0, duration, r.clock.t + 0.001 - stamp, step))
    waiting = [values[2] for t, _, values in r.rpdos if began + 0.002 < t < stamp - 0.001]
    assert waiting and all(milliamps == 0 for milliamps in waiting)      # held for its stamp, not given late
    assert any("follows the stamps" in text for _, text in r.driver.drain_events())


def test_the_drive_counts_as_silent_until_its_count_of_a_stand_still_has_settled(rig):
    """`silent` (the controller's cue to cancel no ramp) lasts until the SYNCs never answered are counted:
    the first answers after a stop are the ones the hub held, and the count they give at once is short.
    Told the silence was over but not yet how long, the controller cancelled a ramp whose touchdown the
    stand-still had put off (bench round 5: 0.70 cm)."""
    from hopper_ros.canbus.driver.stillness import SETTLE

    r = rig().start()
    r.enable(torque=1.0)
    r.drive_alive = False
    r.step(60, command=(MODE_CURRENT, 0.5))
    assert r.driver.silent
    r.drive.discard_syncs()
    r.drive_alive = True
    r.step(2, command=(MODE_CURRENT, 0.5))
    assert r.driver.stillness.answered and not r.driver.stillness.silent and r.driver.silent   # answers, count open
    r.step(round(SETTLE / SETTINGS.sync_period) + 2, command=(MODE_CURRENT, 0.5))
    assert not r.driver.silent and r.driver.frozen_time == pytest.approx(0.06, abs=2 * SETTINGS.sync_period)


def test_command_watchdog_quick_stops_then_disables_and_recovers(rig):
    r = rig().start()
    r.enable()
    r.step(20, command=(MODE_CURRENT, 2.0))
    last_command = r.clock.t
    r.step(60)
    after = [(t, values[0]) for t, _, values in r.rpdos if t > last_command]
    stop_time, first = next((t, cw) for t, cw in after if cw != Command.SWITCH_ON_AND_ENABLE)
    assert first == Command.QUICK_STOP
    timeout, period = SETTINGS.command_timeout, SETTINGS.sync_period
    assert timeout < stop_time - last_command <= timeout + period + 1e-9   # at most one SYNC period late
    assert dedup([cw for t, cw in after if t >= stop_time]) == [Command.QUICK_STOP, Command.DISABLE_VOLTAGE]
    assert all(values[2] == 0 for t, _, values in r.rpdos if t >= stop_time)   # current zeroed with the stop
    disable_time = next(t for t, cw in after if cw == Command.DISABLE_VOLTAGE)
    assert disable_time - stop_time <= SETTINGS.quick_stop_time + 1e-9         # quick stop only briefly
    assert dedup(r.states)[-3:] == [State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED]
    disabled_at = last_command + 0.001 * (r.states[-60:].index(State.SWITCH_ON_DISABLED) + 1)
    assert disabled_at - last_command <= 0.020                                 # issue 17: within 20 ms
    assert r.drive.demand == 0.0
    assert r.driver.counters["watchdog_stops"] == 1 and r.driver.health()[0] == WARN

    # commands that are not valid do not feed the watchdog
    r.enable()
    r.step(40, command=(MODE_CURRENT, math.nan))
    assert r.drive.state is State.SWITCH_ON_DISABLED and r.driver.counters["commands_rejected"] == 40
    r.step(5, command=(7, 1.0))
    assert r.driver.counters["commands_rejected"] == 45
    steps = r.until(lambda: r.drive.state is State.OPERATION_ENABLED, command=(MODE_CURRENT, 2.0))
    assert steps <= 4 and r.driver.counters["watchdog_stops"] == 2


def test_a_ramp_stopped_by_the_watchdog_goes_on_at_its_own_phase_when_its_commands_come_back(rig):
    """A gap in the command stream mid-stance trips the watchdog (current zeroed, quick stop); when the same
    ramp is commanded again, it goes on where its stamp puts it. Started anew from `max_ramp_age` back, the
    stance got the ramp's first part twice (bench round 14: 1.03 cm)."""
    r = rig().start()
    r.enable(torque=1.0)
    tau_0, duration = 6.0, 0.08
    touchdown = r.clock.t + 0.001
    _run_ramp(r, tau_0, duration, touchdown, 15)
    r.step(round(SETTINGS.command_timeout / SETTINGS.sync_period) + 2)      # the stream stops: the watchdog trips
    assert r.driver.counters["watchdog_stops"] == 1 and r.rpdos[-1][2][2] == 0
    resumed = r.clock.t
    seen = _run_ramp(r, tau_0, duration, touchdown, 30)
    assert r.drive.state is State.OPERATION_ENABLED
    on = [(t, milliamps) for t, milliamps in seen if t > resumed + 0.001]
    for t, milliamps in on:
        assert milliamps == pytest.approx(_ramp_milliamps(tau_0, duration, t - touchdown), abs=1)
    assert abs(on[0][1]) < abs(_milliamps(-tau_0)) * (1 - 0.025 / duration)     # not the ramp's start again
    assert r.driver.counters["ramps_begun_late"] == 0


def test_watchdog_trips_at_its_deadline_between_cycles(rig):
    """The node calls watchdog() at watchdog_deadline() instead of waiting for the next SYNC period:
    the quick stop with zero current goes out at once, and not before the deadline."""
    r = rig().start()
    r.enable()
    r.step(5, command=(MODE_CURRENT, 2.0))
    deadline = r.driver.watchdog_deadline()
    assert deadline == pytest.approx(r.clock.t + SETTINGS.command_timeout)
    r.clock.t = deadline                                 # due, not yet past it
    assert not r.driver.watchdog()
    r.clock.t = deadline + 0.0002
    sent_before = len(r.rpdos)
    assert r.driver.watchdog() and r.driver.counters["watchdog_stops"] == 1
    r._settle()
    controlword, _, milliamps = r.rpdos[sent_before][2]
    assert (controlword, milliamps) == (Command.QUICK_STOP, 0)
    assert r.driver.watchdog_deadline() == math.inf and not r.driver.watchdog()   # once per loss
    r.step(3)
    assert r.drive.state is State.SWITCH_ON_DISABLED


def test_fault_in_operation_is_reported_and_reset_only_after_disable(rig):
    r = rig().start()
    r.enable()
    r.drive.inject_fault(eo.ERROR_FOLLOWING, r.clock.t)
    r.step(2, command=(MODE_CURRENT, 0.5))
    status = r.driver.status
    assert status.state is State.FAULT and (status.fault_code, status.fault_text) == (0x8611, "Following error")
    assert r.remote.emcy.active[-1].code == 0x8611                      # canopen decoded the same EMCY
    assert r.driver.health() == (ERROR, "drive fault 0x8611: Following error")
    assert r.driver.counters["faults"] == 1 and r.driver.counters["emcy_received"] == 1
    fault_at = r.clock.t
    r.step(100, command=(MODE_CURRENT, 0.5))                            # the stream goes on: no reset by itself
    assert r.drive.state is State.FAULT
    assert not any(cw & Command.FAULT_RESET for cw in r.controlwords(since=fault_at))
    r.step(3, command=(MODE_DISABLED, 0.0))                            # acknowledgement
    assert r.drive.state is State.SWITCH_ON_DISABLED and r.driver.counters["fault_resets"] == 1
    assert r.remote.emcy.active == []                                   # the drive's "error reset" EMCY
    assert r.driver.status.fault_code == 0x8611                         # the last fault stays readable
    r.enable()
    assert r.driver.health() == (0, "")


def test_heartbeat_loss_disables_and_the_drive_comes_back(rig):
    r = rig().start()
    r.enable()
    r.step(150, command=(MODE_CURRENT, 0.5))
    r.drive_alive = False                                               # the drive goes silent
    lost_at = r.clock.t
    r.until(lambda: r.driver.counters["heartbeat_losses"] == 1, command=(MODE_CURRENT, 0.5))
    assert r.clock.t - lost_at <= 0.3 + 0.1 + 0.002                     # timeout after the last heartbeat
    assert not r.driver.status.heartbeat_ok
    assert r.driver.health() == (ERROR, "drive heartbeat lost: drive disabled")
    r.step(2, command=(MODE_CURRENT, 0.5))
    assert r.rpdos[-1][2][0] == Command.DISABLE_VOLTAGE                  # told to switch off, in case it hears
    r.drive_alive = True
    r.until(lambda: r.driver.status.heartbeat_ok and r.drive.state is State.OPERATION_ENABLED, limit=300,
            command=(MODE_CURRENT, 0.5))


def test_drive_reboot_is_configured_again(rig):
    r = rig().start()
    r.enable()
    r.network.send_message(0, [eo.NmtCommand.RESET_NODE, NODE])         # someone resets the drive
    r.step()
    assert r.driver.counters["drive_bootups"] == 2                      # power-on one and this one
    r.until(lambda: r.driver.phase is Phase.RUNNING, limit=20, command=(MODE_CURRENT, 0.5))
    assert r.drive.value(eo.TPDO_MAPPING, 3) == eo.pdo_mapping_entry(eo.CURRENT_ACTUAL_VALUE, 0, 16)
    r.until(lambda: r.drive.state is State.OPERATION_ENABLED, limit=300, command=(MODE_CURRENT, 0.5))


def test_silent_master_or_broken_bus_leaves_the_drive_safe(rig):
    r = rig().start()
    r.enable()
    r.step(10, command=(MODE_CURRENT, 3.0))
    assert r.drive.demand > 1.0
    r.driver_bus.shutdown()                                             # our transport breaks
    r.step(5, command=(MODE_CURRENT, 3.0))                              # the driver carries on, counting
    assert r.driver.counters["bus_errors"] >= 5
    assert r.driver.health() == (ERROR, "CAN bus error: drive disabled")
    r.step(250)                                                         # the drive misses our heartbeat
    assert r.drive.state is State.FAULT and r.drive.error_code == eo.ERROR_LIFE_GUARD and r.drive.demand == 0.0


def test_error_frame_disables_for_the_holdoff(rig):
    r = rig().start()
    r.enable()
    r.spy_bus.send(can.Message(is_error_frame=True, arbitration_id=0x20000004, data=bytes(8)))
    error_at = r.clock.t
    r.step(5, command=(MODE_CURRENT, 0.5))
    assert r.drive.state is State.SWITCH_ON_DISABLED and r.driver.counters["bus_errors"] == 1
    r.until(lambda: r.drive.state is State.OPERATION_ENABLED, command=(MODE_CURRENT, 0.5))
    assert r.clock.t - error_at >= 0.1                                  # bus_error_holdoff


def test_malformed_frames_are_counted_and_never_fatal(rig):
    r = rig().start()
    r.enable()
    bad = [(0x180 + NODE, b"\x37\x01\x00"), (0x280 + NODE, b"\x00"), (0x80 + NODE, b"\x10\x23\x02"),
           (0x700 + NODE, b""), (0x700 + NODE, b"\x33"), (0x580 + NODE, b"\x60\x40\x60"),
           (0x580 + NODE, bytes([0x4B, 0x41, 0x60, 0, 0x37, 0x01, 0, 0]))]   # well-formed, but nobody asked
    for cob, data in bad:
        r.spy_bus.send(can.Message(arbitration_id=cob, data=data, is_extended_id=False))
    r.step(3, command=(MODE_CURRENT, 0.5))
    assert r.driver.counters["malformed_frames"] == 6
    level, _ = r.driver.health()
    assert level == 0 and r.drive.state is State.OPERATION_ENABLED      # operation goes on
    assert any("malformed frame" in text for _, text in r.driver.drain_events())
    received = r.driver.counters["tpdo_received"]
    r.step(10, command=(MODE_CURRENT, 0.5))
    assert r.driver.counters["tpdo_received"] == received + 20


def test_shutdown_leaves_the_drive_disabled(rig):
    r = rig().start()
    r.enable()
    r.step(10, command=(MODE_CURRENT, 2.0))
    r.driver.begin_shutdown()
    r.until(lambda: r.driver.phase is Phase.STOPPED, limit=100)
    assert r.driver.shutdown_confirmed
    assert r.drive.state is State.SWITCH_ON_DISABLED and r.drive.demand == 0.0
    assert r.drive.nmt_state == NmtState.PRE_OPERATIONAL and r.drive.value(eo.CONSUMER_HEARTBEAT_TIME, 1) == 0
    assert r.controlwords()[-1] == Command.DISABLE_VOLTAGE
    r.driver_alive = False
    r.step(500)                                                         # no heartbeat fault afterwards
    assert r.drive.state is State.SWITCH_ON_DISABLED


def test_blocking_shutdown_pumps_the_bus_itself():
    """shutdown() as the node calls it: real time, the drive served by a thread of its own."""
    channel = f"motor_driver_test_{next(_channels)}"
    driver_bus = can.Bus(interface="virtual", channel=channel)
    drive_bus = can.Bus(interface="virtual", channel=channel)
    drive = Epos2Emulator(drive_bus, HW)
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            now = time.monotonic()
            drive.poll(now)
            drive.control(now, 0, 0.0, drive.demand)
            time.sleep(0.0005)

    server = threading.Thread(target=serve)
    server.start()
    try:
        driver = MotorDriver(driver_bus, HW, SETTINGS)
        end = time.monotonic() + 10.0
        while drive.state is not State.OPERATION_ENABLED:
            driver.command(MODE_CURRENT, 1.0)
            driver.cycle()
            while (frame := driver_bus.recv(timeout=0.001)) is not None:
                driver.handle(frame)
            assert time.monotonic() < end
        assert driver.shutdown() is True            # confirmed within its own bound, shutdown_timeout
        assert drive.state is State.SWITCH_ON_DISABLED
        end = time.monotonic() + 2.0
        while drive.nmt_state != NmtState.PRE_OPERATIONAL:                # the last frame, just sent
            assert time.monotonic() < end
            time.sleep(0.001)
    finally:
        stop.set()
        server.join()
        driver_bus.shutdown()
        drive_bus.shutdown()


def test_configuration_and_bus_choice():
    config = load_motor_driver()
    settings = config.driver
    assert settings.command_timeout == 0.01 and settings.sync_period == 0.001
    assert (config.hardware_file, config.status_period, config.status_decimation) == ("hardware.yaml", 0.1, 1)
    assert dataclasses.replace(settings, command_timeout=0.005).command_timeout == 0.005
    with pytest.raises(ValueError, match="comand_timeout: unknown key"):
        DriverSettings.from_mapping({"comand_timeout": 0.02})
    with pytest.raises(ValueError, match="command_timeout"):
        DriverSettings(command_timeout=-1.0)
    with pytest.raises(ValueError, match="master_node_id"):
        MotorDriver(None, HW, DriverSettings(master_node_id=NODE))
    with pytest.raises(ValueError, match="udp_multicast"):
        open_bus(CanBus("udp_multicast", "239.74.163.2"))
    bus = open_bus(HW.can, interface="virtual", channel="motor_driver_config_test")
    try:
        assert isinstance(bus, can.interfaces.virtual.VirtualBus)
    finally:
        bus.shutdown()
    driver = MotorDriver(None, HW, SETTINGS)
    assert driver.current_for_torque(1.0) == (pytest.approx(1.0 / (K_T * GEAR)), False)
    assert driver.current_for_torque(-100.0) == (-20.0, True)
    assert driver.counts_for_angle(2 * math.pi) == COUNTS_PER_LEG_TURN


def test_the_torque_sent_for_a_ramp_is_what_the_drive_held_less_what_a_stand_still_never_took():
    """What a late ramp owes is its impulse less what the drive was given since its start (skipped.SentTorque): a ramp
    whose start a stand-still's count had moved past the measured touchdown was sent from the touchdown on, and
    paid in full again at the current limit (bench_demo_load --bag: 12 ms at 12.5 N m, the apex 0.75 cm low). What
    was sent while the drive answered no SYNC never reached a robot that ran (its world stood still)."""
    from hopper_ros.canbus.driver.skipped import SentTorque

    sent = SentTorque()
    for k in range(10):                                   # a ramp's settings, one a ms, each held until the next
        sent.add(0.100 + 0.001 * k, -10.0 + k)
    sent.add(0.110, 0.0)
    assert sent.between(0.100, 0.120) == pytest.approx(-0.001 * sum(10.0 - k for k in range(10)))
    assert sent.between(0.105, 0.107) == pytest.approx(-0.001 * (5.0 + 4.0))
    # the drive answered nothing from 0.102 to 0.106: the four settings of that span were never given
    assert sent.between(0.100, 0.120, (0.102, 0.106)) == pytest.approx(-0.001 * (10.0 + 9.0 + 4.0 + 3.0 + 2.0 + 1.0))
    sent.reset()
    assert sent.between(0.0, 1.0) == 0.0
