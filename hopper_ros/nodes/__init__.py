"""The ROS 2 nodes of the hopper graph: thin adapters over the plain modules of hopper_ros.

Importing any node module goes through this package first, so the loopback-only discovery
default is in `os.environ` before a node module imports rclpy (see hopper_ros.runtime.environment).
Node entry points run through `hopper_ros.nodes.common.run_node`, which applies it strictly.
"""

from hopper_ros.runtime.environment import apply_ros_environment as _apply_ros_environment

_apply_ros_environment(strict=False)
