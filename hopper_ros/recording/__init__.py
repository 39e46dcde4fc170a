"""Recording: rosbag2 bags (metadata.yaml + MCAP, cdr, ros2msg schemas embedded) written from
live topics or from the simulated robot in lockstep, read back, inspected and recovered after
a crash. No ROS import at module level except in `recorder` (the rclpy node).

- `schemas`   message definitions (.msg text with dependencies, rosbag2 style) and type hashes
- `bag`       `BagWriter`, `BagReader`, `bag_info`, `recover_bag`: the file format
- `cdr`       column-wise numpy decoding of flat messages (the 1 kHz topics)
- `recorder`  the rclpy side of `hopper bag record` (raw subscriptions into a `BagWriter`)
- `collect`   section 4.1's single-stride experiments on the simulated robot, recorded as a bag
- `experiments`  the experiment variants the collection and the GRF analysis run (ramp,
                 constant torque, none), with the commanded torque recorded
"""
