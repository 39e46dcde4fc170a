"""`hopper demo --rate auto`: the rehearsal's verdict on the nodes' diagnostics (hopper_ros/cli/demo.py).

The rehearsal itself runs in every `make demo`; here its rule, on counters shaped as the nodes report them
(cumulative since each node started: the verdict is on what changed during the rehearsal); and the detector's
deadline, the loop's own period, that the late states are counted against."""

import time

import pytest

from hopper_ros.cli.demo import HEALTH_NODES, REHEARSAL_LATE_MAX, loop_health, rate_not_kept, reported_since


def _diagnostics(samples, late, watchdog_stops=0, resyncs=0):
    return {"event_detector": {"samples": samples, "late_samples": late},
            "motor_driver": {"watchdog_stops": watchdog_stops},
            "sim_robot": {"resyncs": resyncs}}


def test_a_loop_that_keeps_its_deadlines_is_kept():
    before = _diagnostics(5000, 4000, watchdog_stops=2, resyncs=1)      # the start-up's own troubles
    after = _diagnostics(8000, 4300, watchdog_stops=2, resyncs=1)       # 10 % late since
    assert rate_not_kept(loop_health(after, before)) == ""


def test_late_states_watchdog_stops_and_stalls_each_say_why():
    before = _diagnostics(1000, 100)
    late = int(3000 * (REHEARSAL_LATE_MAX + 5) / 100)
    assert rate_not_kept(loop_health(_diagnostics(4000, 100 + late), before)) == \
        f"{REHEARSAL_LATE_MAX + 5:.0f} % of the states late"
    # the rehearsal that let a 1 kHz demo through at 44 % late (4 watchdog stops in its run, 0.55 cm off)
    assert rate_not_kept(loop_health(_diagnostics(4000, 100 + 1320), before)) == "44 % of the states late"
    assert rate_not_kept(loop_health(_diagnostics(4000, 200, watchdog_stops=3), before)) == \
        "3 watchdog stops of the drive"
    both = rate_not_kept(loop_health(_diagnostics(4000, 2900, watchdog_stops=1), before))
    assert both == "93 % of the states late, 1 watchdog stops of the drive"


def test_a_stall_of_the_robot_alone_does_not_reject_the_rate():
    """The machine stopping the simulated robot's process stops it at any rate: under bench_demo_load's stalls
    the 1 kHz loop did as well as the 500 Hz one those stalls had sent the demo to."""
    before = _diagnostics(1000, 10)
    assert rate_not_kept(loop_health(_diagnostics(4000, 40, resyncs=2), before)) == ""


@pytest.mark.parametrize("hardware_file, late", [("hardware.yaml", 2), ("demo/hardware_500hz.yaml", 1)])
def test_a_state_is_late_after_the_loops_own_period(rclpy_session, monkeypatch, hardware_file, late):
    """The detector's deadline is the sample period of its hardware file (config/sensing.yaml sample_deadline 0): 1 ms
    at 1 kHz, 2 ms for the demo at 500 Hz, where a 1 ms deadline counted most states of a loop that kept its rate
    late (34-90 % in the 500 Hz demos of 2026-11-28)."""
    from types import SimpleNamespace

    from hopper_ros.msg import BodyState
    from hopper_ros.nodes import event_detector
    from hopper_ros.nodes.stamps import to_stamp

    node = event_detector.EventDetectorNode(cli_args=["--ros-args", "-p", f"hardware_file:={hardware_file}"])
    now = 1.8e9        # the node's host clock held still: each state's age is what the stamp says, whatever the load
    monkeypatch.setattr(event_detector, "time", SimpleNamespace(time=lambda: now, perf_counter=time.perf_counter))
    try:
        for age in (0.0002, 0.0015, 0.004):      # on time; within 2 ms; past both
            msg = BodyState()
            msg.header.stamp = to_stamp(now - age)
            node._on_state(msg)
        assert node.late_samples == late
    finally:
        node.destroy_node()


def test_a_node_that_did_not_report_is_no_verdict():
    assert rate_not_kept(loop_health({}, {})) == ""


def test_the_counters_are_taken_only_once_every_node_has_reported_since_the_graph_came_up():
    """A node that has not reported since the graph came up (the simulated robot reports 1 s after it starts)
    would have its start-up's stalls counted as the rehearsal's: 1 kHz rehearsals with 0-4 % of the states late
    were rejected for the stalls of a container loading its nodes, before the drive was enabled."""
    came_up = 100.0
    reported = {name: came_up + 0.3 for name in HEALTH_NODES}
    assert reported_since(reported, came_up)
    assert not reported_since(reported | {"sim_robot": came_up - 0.7}, came_up)
    assert not reported_since({name: t for name, t in reported.items() if name != "sim_robot"}, came_up)
    # and what a snapshot without the driver's report would count: its start-up's watchdog stop as the rehearsal's
    before = {"event_detector": {"samples": 500, "late_samples": 10}, "sim_robot": {"resyncs": 2}}
    after = _diagnostics(3500, 100, watchdog_stops=1, resyncs=2)
    assert rate_not_kept(loop_health(after, before)) == "1 watchdog stops of the drive"
