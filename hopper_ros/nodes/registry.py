"""The node registry: every node of the graph, by the name `hopper run NAME` and
`ros2 run hopper_ros NAME` use, mapped to its `module:function` entry point, and every
composable node (a node class a `component_container` can load).

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
    "component_container": "hopper_ros.nodes.component_container:main",
}

# The composable nodes: a launch file's `composable_node` `plugin` (pkg hopper_ros), as a C++
# component's registered class name, mapped to the node's class (`module:Class`).
COMPONENTS = {
    "hopper_ros::SetpointScheduler": "hopper_ros.nodes.setpoint_scheduler:SetpointScheduler",
    "hopper_ros::StridePredictor": "hopper_ros.nodes.stride_predictor:StridePredictor",
    "hopper_ros::MotorDriver": "hopper_ros.nodes.motor_driver:MotorDriverNode",
    "hopper_ros::SimRobot": "hopper_ros.nodes.sim_robot:SimRobotNode",
    "hopper_ros::EncoderBridge": "hopper_ros.nodes.encoder_bridge:EncoderBridgeNode",
    "hopper_ros::StateEstimator": "hopper_ros.nodes.state_estimator:StateEstimatorNode",
    "hopper_ros::EventDetector": "hopper_ros.nodes.event_detector:EventDetectorNode",
    "hopper_ros::DeadbeatController": "hopper_ros.nodes.deadbeat_controller:DeadbeatControllerNode",
}
