"""`hopper demo --rate auto`: the rehearsal's verdict on the nodes' diagnostics (hopper_ros/cli/demo.py).

The rehearsal itself runs in every `make demo`; here its rule, on counters shaped as the nodes report them
(cumulative since each node started: the verdict is on what changed during the rehearsal)."""

from hopper_ros.cli.demo import REHEARSAL_LATE_MAX, loop_health, rate_not_kept


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
    assert rate_not_kept(loop_health(_diagnostics(4000, 100 + late), before)) == "55 % of the states late"
    assert rate_not_kept(loop_health(_diagnostics(4000, 200, watchdog_stops=3), before)) == \
        "3 watchdog stops of the drive"
    both = rate_not_kept(loop_health(_diagnostics(4000, 2900, resyncs=2), before))
    assert both == "93 % of the states late, 2 stalls of the robot"
    # at 500 Hz the detector's 1 ms deadline is half a period: only the stops and stalls count
    assert rate_not_kept(loop_health(_diagnostics(4000, 2900, resyncs=2), before), None) == "2 stalls of the robot"


def test_a_node_that_did_not_report_is_no_verdict():
    assert rate_not_kept(loop_health({}, {})) == ""
