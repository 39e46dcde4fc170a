"""How the stack's processes run, below the nodes, the launcher, the recorder and the CLI; no domain
knowledge, no node.

- `environment`  the ROS environment of a process: DDS on loopback, discovery range, stop signals,
                 SCHED_FIFO priority, a free domain id
- `messages`     ROS message helpers that need no node: a message class by its type name, to dict/YAML
- `periodic`     PeriodicThread: an action on time on a (real-time) thread of its own
- `gaps`         GapHistogram: the gaps of a periodic stream (the motor command stream)
"""
