"""Recording: rosbag2 bags (metadata.yaml + MCAP, cdr, ros2msg schemas embedded) written from
live topics (or from the simulated robot in lockstep, `hopper_ros.harness.collect`), read back,
inspected and recovered after a crash, and the recording data model the identification reads.
No ROS import at module level except in `recorder` (the rclpy node).

- `schemas`   message definitions (.msg text with dependencies, rosbag2 style) and type hashes
- `bag/`      the file format: `metadata` (BagError, topics, metadata.yaml), `writer` (`BagWriter`),
              `reader` (`BagReader`, tolerant of an unfinished MCAP), `recovery` (`bag_info`, `recover_bag`)
- `cdr`       column-wise numpy decoding of flat messages (the 1 kHz topics)
- `recorder`  the rclpy side of `hopper bag record` (raw subscriptions into a `BagWriter`)
- `recordings` recordings as 1 kHz arrays: bags of our recorder, CSV `t,y,z,theta,tau[,phase]`
- `collect`   transitional alias of `hopper_ros.harness.collect` (see its docstring)
"""
