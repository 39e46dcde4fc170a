"""The node registry: every node of the graph, by the name `hopper run NAME` and
`ros2 run hopper_ros NAME` use, mapped to its `module:function` entry point.

This file is the single source of truth: setup.py reads it for the console scripts and the
CMake build reads it for the `ros2 run` wrappers. It must stay importable without ROS.
"""

NODES = {
    "setpoint_scheduler": "hopper_ros.nodes.setpoint_scheduler:main",
    "stride_predictor": "hopper_ros.nodes.stride_predictor:main",
    "motor_driver": "hopper_ros.nodes.motor_driver:main",
    "sim_robot": "hopper_ros.nodes.sim_robot:main",
    "encoder_bridge": "hopper_ros.nodes.encoder_bridge:main",
    "state_estimator": "hopper_ros.nodes.state_estimator:main",
    "event_detector": "hopper_ros.nodes.event_detector:main",
    "deadbeat_controller": "hopper_ros.nodes.deadbeat_controller:main",
}
