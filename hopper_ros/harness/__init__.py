"""Harnesses: the simulated robot (`hopper_ros.sim`) driven in-process, in lockstep, by the
libraries' own code, for the tests, the benchmarks and the CLI's offline commands. The one
package that may import both sim/ and the libraries; no library package imports it.

- `lockstep`        the deadbeat controller closing the loop on SimRobot (true state, no ROS)
- `graph_lockstep`  the whole node graph's logic in one process (packets, CAN frames, no ROS)
- `sensing_evaluation`  SimRobot experiments recorded and detected events scored against truth
- `experiments`     section 4.1's single-stride experiment variants (ramp, constant torque, none)
- `collect`         those experiments recorded as a bag (and CSV), `hopper collect`
- `grf`             section 4.4's GRF experiments, one stride per torque profile
"""
