"""Issue 29: the causes of the demo's falls under load, each in the in-process graph (fast, no ROS).

hopper_ros.harness.graph_lockstep runs the modules of every node of the demo in one process, the
host clock apart from the simulated robot's (`host_delay`): the loads of bench/bench_demo_load.py
become the delays they cause. Each test failed before its fix (the robot fell, or its apex missed
the setpoint by centimetres); the figures of the real graph under load are the bench's.
"""

from __future__ import annotations

import math

import pytest

from hopper_ros.canbus.driver import load_motor_driver
from hopper_ros.control.config import load_control
from hopper_ros.control.stride_machine import Phase
from hopper_ros.control.deadbeat import DeadbeatController
from hopper_ros.hardware.config import load_hardware
from hopper_ros.harness.graph_lockstep import GraphLockstep
from hopper_ros.physics.params import load_params
from hopper_ros.sensing.samples import EventType
from hopper_ros.sim.plant import ZDOT
from hopper_ros.sim.config import load_sim_config

HARDWARE = load_hardware()
CONTROL = load_control()
DRIVER = load_motor_driver().driver                # the demo's (launch/demo.launch.yaml: motor_driver.yaml)
SETPOINT = (0.39, 2.0)
STRIDES = 8


def demo_graph(host_delay=lambda t: 0.0, event_delay=lambda t: 0.0):
    """The demo's loop (control.yaml, motor_driver.yaml) in one process."""
    return GraphLockstep(load_sim_config(), HARDWARE, DeadbeatController(load_params(), CONTROL.deadbeat),
                         driver_settings=DRIVER, stride_settings=CONTROL.stride, host_delay=host_delay,
                         event_delay=event_delay)


def release_after_throw(graph, run):
    """SETPOINT's throw: the robot held at its apex while the drive comes up, then released."""
    graph.set_setpoint(*SETPOINT)
    graph.robot.throw(*SETPOINT, graph.controller.neutral_angle(SETPOINT[1]), lead_time=0.05, hold=True)
    while graph.robot.t < 0.5:
        graph.step(run)
    graph.robot.plant.release()


def run_graph(host_delay=lambda t: 0.0, graph_hook=None, event_delay=lambda t: 0.0):
    """The demo's loop for STRIDES strides at SETPOINT."""
    graph = demo_graph(host_delay, event_delay)
    if graph_hook is not None:
        graph_hook(graph)
    try:
        run = graph.run([SETPOINT] * STRIDES)
    finally:
        graph.close()
    return graph, run


def apex_errors(run) -> list[float]:
    """|apex height - setpoint| [m] of each stride after the first."""
    return [abs(apex[1] - SETPOINT[0]) for apex in run.true_apexes[2:STRIDES + 1]]


def assert_hops_as_unloaded(graph, run):
    assert not run.fell and len(run.true_apexes) > STRIDES
    assert max(apex_errors(run)) < 0.005                        # the 0.5 cm
    stances = run.stances
    assert stances.stances >= STRIDES and stances.without_torque == 0 and stances.late == 0, stances.onsets
    assert graph.driver.counters["watchdog_stops"] == 0


def test_unloaded_reference():
    graph, run = run_graph()
    assert_hops_as_unloaded(graph, run)
    assert graph.sensing.estimator.clock.anchors == 1 and graph.policy.counters["touchdowns_missed"] == 0


def test_the_500hz_graph_hops_as_closely_as_the_1khz_one():
    """The demo's 500 Hz graph (`make demo` where 1 kHz is not kept: demo/hardware_500hz.yaml,
    demo/motor_driver_500hz.yaml, the driver's SYNC every 2 ms as the launch files set it) in one
    process: each stance gets its whole ramp, so the apexes spread about as at 1 kHz (standard deviation
    0.042 cm against 0.037). The harness gave the driver motor_driver.yaml's 1 ms SYNC period while it
    cycled it every 2 ms: the ramp averaged over the first half of each period it is held, the touchdown's
    period getting the wrong share by its phase (0.107 cm)."""
    import dataclasses
    import statistics

    def spread(hardware, driver_file, strides=16):
        config = dataclasses.replace(load_sim_config(), period=hardware.microcontroller.sample_period)
        graph = GraphLockstep(config, hardware, DeadbeatController(load_params(), CONTROL.deadbeat),
                              driver_settings=load_motor_driver(driver_file).driver, stride_settings=CONTROL.stride)
        try:
            run = graph.run([SETPOINT] * strides)
        finally:
            graph.close()
        assert not run.fell and len(run.true_apexes) > strides
        return statistics.pstdev(apex[1] - SETPOINT[0] for apex in run.true_apexes[2:strides + 1])

    half_rate = spread(load_hardware("demo/hardware_500hz.yaml"), "demo/motor_driver_500hz.yaml")
    full_rate = spread(HARDWARE, "motor_driver.yaml")
    assert half_rate < 1.5 * full_rate, (half_rate, full_rate)


def test_a_robot_running_late_through_a_touchdown_keeps_its_ramp_where_it_touches_down():
    """The simulated robot runs 5 ms behind for 20 ms from just before a pre-touchdown event (its process
    starved, not stopped: it catches up, its drive taking the queued SYNC periods one a step, so it feels each
    setting at the instant it was meant for). The sensing clock took its late packets for a stand-still and
    re-anchored by 5 ms (clock_max_error was 1 ms): the measured touchdown, stamped on that mapping, moved the
    ramp 5 ms off the touchdown the driver's own timeline had right (0.84 cm). Lateness below the shortest
    stand-still (clock_max_error) moves no stamp now."""
    graph, run = run_graph(lambda t: 0.005 if 2.02 <= t < 2.04 else 0.0)
    assert_hops_as_unloaded(graph, run)
    assert graph.policy.prediction_early_max < 0.001 and graph.sensing.estimator.clock.anchors == 1


@pytest.mark.parametrize("skip_at", [1.0, 1.1, 1.2, 1.3])
def test_the_simulated_robot_skipping_time_in_flight(skip_at):
    """Cause 1: the simulated robot stalled beyond RESYNC_AFTER skips the time it missed: from then on
    every packet arrives 80 ms after its instant on the old clock mapping. The mapping, re-anchored
    upwards only beyond 0.1 s and slewing 0.5 ms/s, left every stamp 80 ms old: every stance ramp
    cancelled, the robot fell. Now re-anchored within clock_reanchor_after, the event detector
    following the step of its stamps."""
    graph, run = run_graph(lambda t: 0.08 if t >= skip_at else 0.0)
    assert_hops_as_unloaded(graph, run)
    assert graph.sensing.estimator.clock.anchors == 2 and graph.sensing.detector.counters["track_lost"] == 0


def test_late_first_packets():
    """Cause 2: the first packets arrive 40 ms late (a burst at start-up): the mapping anchored on them
    put every stamp 40 ms ahead and the driver held each stance ramp 40 ms: the robot fell."""
    graph, run = run_graph(lambda t: max(0.0, 0.04 - t))
    assert_hops_as_unloaded(graph, run)
    assert graph.sensing.estimator.clock.anchors == 2


@pytest.mark.parametrize("late", [0.008, 0.016])
def test_gait_events_that_reach_the_controller_late(late):
    """The loop's container starved by a real-time process of its priority (bench_demo_load: busy up
    to 8 ms at a time, a backlog behind it), its controller's repeats on time from their thread: every
    gait event and apex reaches the controller `late`. The pre-touchdown event comes ahead of its time
    (`pre_touchdown_lead`, 20 ms), the leg is let go and the ramp scheduled at the event's time, so
    the stance ramps start on time. Before (the event 1 ms ahead, acted on when heard) a pre-touchdown
    heard after the predicted touchdown sent the ramp late: 16 ms late, an apex error of 8 cm; in the
    bench, its torque reached the leg 5.4 ms after a touchdown (1.15 cm)."""
    graph, run = run_graph(event_delay=lambda t: late)
    assert_hops_as_unloaded(graph, run)


def stall_in_a_stance(into_stance, length, caught_up=False):
    """The graph with the simulated robot's process stalled for `length` from `into_stance` after the
    third touchdown on (negative: between the second pre-touchdown event and the touchdown). A stall
    is the world standing still (a step of the packets' delay) or, `caught_up`, the robot running
    late and then catching up (its packets in a burst: the delay falls back to 0)."""
    freeze = {"at": None, "touchdowns": 0, "contact": False}

    def hook(graph):
        def host_delay(t):
            contact = graph.robot.plant.in_contact
            freeze["touchdowns"] += contact and not freeze["contact"]
            freeze["contact"] = contact
            if freeze["at"] is None and into_stance < 0 and freeze["touchdowns"] == 2 and not contact \
                    and graph.policy.phase is Phase.PRE_TOUCHDOWN:
                freeze["at"] = t                  # between the pre-touchdown event and the touchdown
            if freeze["at"] is None and into_stance >= 0 and freeze["touchdowns"] == 3:
                freeze["at"] = t + into_stance
            if freeze["at"] is None or t < freeze["at"]:
                return 0.0
            return max(0.0, length - (t - freeze["at"])) if caught_up else length
        graph.host_delay = host_delay

    graph, run = run_graph(graph_hook=hook)
    assert freeze["at"] is not None
    return graph, run


@pytest.mark.parametrize("into_stance", [-0.005, 0.0, 0.005, 0.02, 0.04])
def test_the_simulated_robot_frozen_in_a_stance(into_stance):
    """Cause 3: the simulated robot's process stops in a stance for longer than it catches up, and its
    world stands still: the driver's ramp ran on on the host clock and was over when the robot went
    on (that stance pushed with a fraction of tau_0, the apex 2-3 cm low, the robot fell when the next
    stride needed the torque limit). The drive answers none of the SYNCs of that time (sim/runner.py),
    the driver holds the ramp while it is silent and moves it by the SYNCs left unanswered; the
    controller cancels no ramp while the drive is silent (frozen just before the touchdown, the
    touchdown is heard only after the freeze: a cancel then lost the ramp's start)."""
    length = 0.08
    graph, run = stall_in_a_stance(into_stance, length)
    assert_hops_as_unloaded(graph, run)
    # the drive answered none of the stall's SYNCs: the driver knows how long the robot stood still
    assert abs(graph.driver.frozen_time - length) <= 1.5 * HARDWARE.microcontroller.sample_period
    assert graph.policy.counters["touchdowns_missed"] == 0
    if into_stance > 0:
        assert graph.driver.counters["ramp_held_syncs"] > 0


@pytest.mark.parametrize("into_stance", [-0.005, 0.005, 0.02])
def test_a_short_stall_of_the_simulated_robot_is_caught_up(into_stance):
    """A stall shorter than sim/runner.py's RESYNC_AFTER is caught up: the robot ran late, its drive
    taking the driver's frames one SYNC period a step, so it felt the ramp as sent. The driver, whose
    answers came late, neither holds the ramp nor counts the robot as standing still (it did: its held
    ramps stretched stances under load, the apex 0.5-0.8 cm off)."""
    graph, run = stall_in_a_stance(into_stance, 0.015, caught_up=True)
    assert_hops_as_unloaded(graph, run)
    assert graph.driver.frozen_time == 0.0 and graph.driver.counters["ramp_held_syncs"] == 0


def test_sensing_that_stops_while_hopping_disables_the_drive():
    """The sensing chain dies (the estimator or the detector killed, each a process of its own in
    demo_500hz.launch.yaml): the controller's repeats go on and would hold the leg or run a ramp
    scheduled from the last events, whatever the robot does. No gait event for sensing_timeout while
    hopping: the drive is disabled (no torque from a stale state); events again (the node respawned,
    the robot thrown): hopping resumes."""
    from hopper_ros.canbus.epos2_objects import State
    from hopper_ros.harness.graph_lockstep import GraphRun
    from hopper_ros.sensing.pipeline import PipelineOutput

    dead_from, dead_to = 1.6, 3.0
    graph = demo_graph()
    process = graph.sensing.process
    graph.sensing.process = lambda datagram, received: (PipelineOutput(None) if dead_from <= graph.robot.t < dead_to
                                                         else process(datagram, received))
    run, enabled = GraphRun(), []
    try:
        release_after_throw(graph, run)
        while graph.robot.t < dead_to + 0.3:
            graph.step(run)
            enabled.append((graph.robot.t, graph.robot.drive.state is State.OPERATION_ENABLED))
        assert graph.policy.counters["sensing_lost"] == 1
        lost = dead_from + CONTROL.stride.sensing_timeout
        assert all(on for t, on in enabled if t < dead_from)
        assert not any(on for t, on in enabled if lost + 0.01 <= t < dead_to), "the drive stayed enabled, blind"
        # the chain back (respawned), the robot thrown again: the strides resume
        hopped = len(run.true_apexes)
        graph.robot.throw(*SETPOINT, graph.controller.neutral_angle(SETPOINT[1]), lead_time=0.05)
        fell = run.fell
        while len(run.true_apexes) < hopped + 6 and graph.robot.t < dead_to + 6.0:
            graph.step(run)
        assert not graph.policy.sensing_lost and len(run.true_apexes) >= hopped + 6
        assert abs(run.true_apexes[-1][1] - SETPOINT[0]) < 0.005 and not graph.robot.plant.fallen, (fell, run.true_apexes[-3:])
    finally:
        graph.close()


def test_a_drive_start_up_error_before_the_throw_does_not_keep_the_drive_off():
    """Start-up ordering: the motor driver started before the simulated robot's hub answered, reported
    ERROR once ("drive start-up failed: SDO timed out") and configured the drive 0.25 s later. The
    controller had latched its safe state on that error: it commanded the drive disabled until an
    apex, the robot was never thrown (the demo waits for an enabled drive), the graph never came up."""
    from hopper_ros.control.stride_machine import MODE_DISABLED, MODE_POSITION
    from hopper_ros.control.stride_policy import StridePolicy

    policy = StridePolicy(DeadbeatController(load_params(), CONTROL.deadbeat), CONTROL.stride)
    policy.on_drive_fault("drive start-up failed: SDO 0x1017:00 timed out")
    policy.on_setpoint(*SETPOINT)
    # acknowledged (the driver resets a drive fault once the stream says MODE_DISABLED), then held
    acknowledge = CONTROL.stride.fault_acknowledge
    assert policy.command(0.0).mode == MODE_DISABLED and policy.command(acknowledge / 2).mode == MODE_DISABLED
    assert policy.command(acknowledge + 1e-3).mode == MODE_POSITION
    assert policy.counters["faults"] == 1 and policy.phase is Phase.INITIALISE


@pytest.mark.parametrize("after_apex", [0.0, 0.17, 0.185, 0.21, 0.3])   # descent, 20 ms and 5 ms before the
def test_a_drive_fault_while_hopping_costs_no_fall(after_apex):           # touchdown, stance, ascent
    """The drive faults while the robot hops (in a soak: its heartbeat consumer, the real-time PC
    stalled 15 ms). The controller acknowledges it (MODE_DISABLED, the driver's cue to reset it),
    the stance gets no position hold, and once the drive is back the stride goes on: the robot hops
    on at the setpoint. Before: the fault was acknowledged only by a sensing chain silent for 500 ms
    (the drive stayed faulted, the robot fell after every throw: 63 times in a soak); then after 0.1 s
    with the stride SAFE until the next apex and the leg held in position through the stance, which
    threw the robot backwards (a fault in the descent or the stance: a fall within 2 strides); and the
    faulted stride's apex, learned, drove the bias to its bound (a fall strides later)."""
    from hopper_ros.canbus.epos2_objects import State
    from hopper_ros.harness.graph_lockstep import GraphRun

    graph = demo_graph()
    run = GraphRun()
    try:
        release_after_throw(graph, run)
        while len(run.true_apexes) < 4:
            graph.step(run)
        fault_at = graph.robot.t + after_apex
        while graph.robot.t < fault_at:
            graph.step(run)
        graph.robot.drive.inject_fault(0x8130, graph.robot.t)
        before = len(run.true_apexes)
        while not run.fell and len(run.true_apexes) < before + 5:
            graph.step(run)
        assert not run.fell, run.true_apexes[before - 1:]
        assert graph.policy.counters["faults"] == 1 and graph.driver.counters["fault_resets"] >= 1
        assert graph.robot.drive.state is State.OPERATION_ENABLED
        # back at the setpoint, height and speed, from the third stride after the faulted one: the ones between
        # may be torque-limited, trading height for the speed the faulted stance lost (deadbeat.py, a setpoint
        # out of the torque's reach; before, the height was kept and the speed came back over the same strides)
        assert all(abs(height - SETPOINT[0]) < 0.005 and abs(speed - SETPOINT[1]) < 0.05
                   for _, height, speed in run.true_apexes[before + 3:]), run.true_apexes[before - 1:]
    finally:
        graph.close()


@pytest.mark.parametrize("second_fault", [0.07, 0.12])
def test_two_drive_faults_in_one_flight_cost_no_fall(second_fault):
    """The soak's fall (docs/sensing.md, the hour on 210e841): the whole graph stalled three times 100 ms apart, the
    drive faulted at an apex and again in the leg's swing, each time disabled until the stall ended and the fault
    was acknowledged, some 50 ms (here: faults injected at an apex and `second_fault` later, acknowledged for 50 ms).
    The swing began late, and the pre-touchdown came while the leg still swung: let go there (the thesis's release),
    it swung past its angle and the robot fell (before: both cases fell, in the faulted stride or the next, whose low
    apex left too short a flight for the swing). Held until just before the touchdown, the robot hops on."""
    import dataclasses

    from hopper_ros.harness.graph_lockstep import GraphRun

    stride = dataclasses.replace(CONTROL.stride, fault_acknowledge=0.05)
    graph = GraphLockstep(load_sim_config(), HARDWARE, DeadbeatController(load_params(), CONTROL.deadbeat),
                          driver_settings=DRIVER, stride_settings=stride)
    run = GraphRun()
    try:
        release_after_throw(graph, run)
        while len(run.true_apexes) < 4:
            graph.step(run)
        before = len(run.true_apexes)
        graph.robot.drive.inject_fault(0x8130, graph.robot.t)
        second_at = graph.robot.t + second_fault
        while graph.robot.t < second_at:
            graph.step(run)
        graph.robot.drive.inject_fault(0x8130, graph.robot.t)
        while not run.fell and len(run.true_apexes) < before + 4:
            graph.step(run)
        assert not run.fell, run.true_apexes[before - 1:]
        assert graph.policy.counters["faults"] == 2 and graph.policy.counters["releases_held"] >= 1
        assert abs(run.true_apexes[-1][1] - SETPOINT[0]) < 0.01, run.true_apexes[before - 1:]
    finally:
        graph.close()


def pre_touchdowns_detected_at(stall_at=None, length=0.0):
    """The instants (sample times) at which the pre-touchdown events were detected, in a run with the
    simulated robot stopped for `length` from the sample at `stall_at` on (its world standing still)."""
    seen = []

    def hook(graph):
        on_event = graph._on_event

        def record(event, run):
            if event.kind is EventType.PRE_TOUCHDOWN:
                seen.append(event.detected_at)
            on_event(event, run)
        graph._on_event = record
        if stall_at is not None:
            graph.host_delay = lambda t: length if t >= stall_at - 1e-9 else 0.0

    graph, run = run_graph(graph_hook=hook)
    return graph, run, seen


@pytest.mark.parametrize("length", [0.03, 0.08, 0.14])
def test_a_stop_of_the_simulated_robot_just_before_its_pre_touchdown_event(length):
    """The simulated robot stops at the very sample on which the pre-touchdown event would be detected:
    the event comes on the first state after the stop. Stamped at once on the sensing clock as it stood
    before (the estimator re-anchors on the second late packet), its predicted touchdown lay the stop's
    length in the past and the controller cancelled the stance ramp (bench_demo_load round 3: 0.68 cm).
    Now that first sample waits for the next one, which says the mapping it is on."""
    _, _, unstopped = pre_touchdowns_detected_at()
    stall_at = unstopped[2]                          # sample times are the stamps of an unloaded run
    graph, run, stopped = pre_touchdowns_detected_at(stall_at, length)
    assert stopped[2] == pytest.approx(stall_at + length, abs=1e-6)   # the event on the first state after the stop
    assert_hops_as_unloaded(graph, run)
    assert graph.policy.counters["touchdowns_missed"] == 0


def stop_before_a_touchdown(lead, length, which=3):
    """The graph with the simulated robot stopped for `length` from `lead` before its `which`-th touchdown
    (the time to it from the plant's flight, leg held), its world standing still."""
    stop = {"at": None, "touchdowns": 0, "contact": False}

    def hook(graph):
        def host_delay(t):
            plant = graph.robot.plant
            contact = plant.in_contact
            stop["touchdowns"] += contact and not stop["contact"]
            stop["contact"] = contact
            if stop["at"] is None and stop["touchdowns"] == which - 1 and not contact and plant.state[ZDOT] < 0:
                height, speed, gravity = plant.toe_height, plant.state[ZDOT], plant.gravity
                if (speed + math.sqrt(speed * speed + 2.0 * gravity * height)) / gravity <= lead:
                    stop["at"] = t
            return 0.0 if stop["at"] is None or t < stop["at"] else length
        graph.host_delay = host_delay

    graph, run = run_graph(graph_hook=hook)
    assert stop["at"] is not None
    return graph, run


@pytest.mark.parametrize("lead", [0.001, 0.002, 0.005])
def test_a_stop_of_the_simulated_robot_just_before_a_touchdown(lead):
    """Stopped 120 ms a few ms before a touchdown: the touchdown is measured right after the stop, on the
    sensing clock re-anchored by it, while the driver still holds the ramp predicted on the old one by
    its own count of the stop. It took the measured stamp for one of the old clock and moved it by the
    whole stop: the stance had no torque, the apex 7.8 and 12.2 cm off (stopped 1 and 2 ms before).
    `MotorCommand.clock_offset` now tells it which clock the stamp is on."""
    graph, run = stop_before_a_touchdown(lead, 0.12)
    assert_hops_as_unloaded(graph, run)
    assert graph.policy.counters["touchdowns_missed"] == 0
