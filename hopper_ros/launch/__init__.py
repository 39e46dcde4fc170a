"""Launch files and the process supervisor behind `hopper launch`. No ROS import.

Launch files are ros2 launch's YAML front end (launch_yaml with launch_ros's `node` and
`node_container`), so a file of nodes runs with `ros2 launch hopper_ros FILE` on a machine with
ROS 2 and with `hopper launch FILE` here (containers: hopper launch only, see below). The files live in `launch/` (installed by CMake to
`share/hopper_ros/launch/`). What `hopper launch` supports of the format:

    launch:
      - arg:                          # a launch argument: `hopper launch FILE rate:=500`
          name: rate
          default: "1000"             # without a default the argument is required
          description: samples per second
      - let: {name: ns, value: /hopper}          # a launch configuration
      - node:                         # one process per node, started in file order
          pkg: hopper_ros             # required: this package
          exec: sim_robot             # required: a node of hopper_ros/nodes/registry.py
          name: sim_robot             # ROS node name   (-r __node:=...)
          namespace: $(var ns)        # ROS namespace   (-r __ns:=...)
          param:                      # parameters     (-p name:=value; rcl reads the value as YAML)
            - {name: mode, value: realtime}
            - {name: gains, param: [{name: kp, value: 1.5}]}   # nested: gains.kp
            - {from: params.yaml}     # a ROS parameter file (--params-file): absolute, next to the
                                      #   launch file, or in config/
          remap:                      # remappings     (-r from:=to)
            - {from: apex, to: /events/apex}
          env:                        # environment of the node's process
            - {name: HOPPER_REALTIME_PRIORITY, value: "50"}   # SCHED_FIFO priority (hopper_ros.runtime.environment)
          args: "--extra 1"           # arguments after --ros-args ... --
          ros_args: "--log-level debug"   # more ROS arguments
          output: screen              # accepted; hopper launch always relays the output
          on_exit: shutdown           # accepted; hopper launch stops all when a node ends (but see respawn)
          respawn: true               # started again when it ends by itself (launch_ros's Node), after
          respawn_delay: 1.0          #   this many seconds (default 0); the others run on. Not with on_exit
          sigterm_timeout: 5          # s from SIGINT to SIGTERM when stopping (ros2 launch's meaning)
          sigkill_timeout: 5          # s from SIGTERM to SIGKILL
          if: $(var with_sim)         # conditions (also on arg and let): true/false/1/0
          unless: ...
      - node_container:               # several nodes in ONE process on ONE executor (launch_ros's
          pkg: hopper_ros             #   ComposableNodeContainer); the keys of `node` but `args`
          exec: component_container   # required: our container (see below)
          name: sensing               # required, as in launch_ros (the container is a node too)
          namespace: ""               # required, as in launch_ros ("" = none)
          env: [...]                  # the process's: HOPPER_REALTIME_PRIORITY holds for every node in it
          composable_node:            # loaded in this order (launch_ros's ComposableNode.parse)
            - pkg: hopper_ros         # required: this package
              plugin: hopper_ros::EncoderBridge   # required: COMPONENTS of hopper_ros/nodes/registry.py
              name: encoder_bridge    # required
              namespace: $(var ns)    # optional: the node's own; the container's is not inherited
              param: [...]            # as for `node` (a `from` file too)
              remap: [...]            # as for `node`, applied to this node only
              extra_arg:              # only this one: the node's subscriptions take the container's
                - {name: use_intra_process_comms, value: "true"}   # messages in-process (rclcpp's meaning)
              if: ...                 # conditions, as for `node`

A container runs `python -m hopper_ros.cli run component_container --ros-args ... -- --components
JSON` (hopper_ros/nodes/component_container.py): each composable node built from its own class
with its own arguments, all on run_node's executor, the hand-over between them in-process where
use_intra_process_comms says so (hopper_ros/nodes/intra_process.py); each node stays runnable
alone (`hopper run NODE`). What differs from ros2 launch, and why: in ROS the container is
rclcpp_components' `component_container` and launch_ros loads the nodes into it through the
container's `_container/load_node` service (composition_interfaces). An rclcpp container loads
C++ classes only and composition_interfaces is not among the PyPI wheels, so `pkg:
rclcpp_components` (and `component_container_mt`, `_isolated`: one executor here) is refused, the
container is hopper_ros's own executable (also `ros2 run hopper_ros component_container`), and it
takes its nodes on its command line, not by service: `ros2 launch` on a ROS 2 machine would start
it without nodes and wait for the service, so files with a node_container run with `hopper
launch` (demo_500hz.launch.yaml, all separate processes, runs under both). `load_composable_node`
(loading into a running container) is not supported. A plugin is named like a C++ component's
registered class (`hopper_ros::EncoderBridge`) and maps to a Python class in the registry.

Substitutions: `$(var NAME)`, `$(env NAME [DEFAULT])`, `$(optenv NAME [DEFAULT])`,
`$(find-pkg-share PKG)` (hopper_ros: the folder holding config/ and launch/), `$(dirname)`.
Anything else of the format (groups, includes, other actions, other node attributes) is
refused with the file, the entry and the key named, rather than silently ignored.

There is no extension key for our extras: ros2 launch rejects any key of a `node` it does not
know (launch/frontend/expose.py checks that every key was parsed), so the real-time priority is
the standard `env` entry HOPPER_REALTIME_PRIORITY, which ros2 launch passes to the node as well,
and the stop timeouts are launch's own `sigterm_timeout` / `sigkill_timeout`.

Each node runs as `python -m hopper_ros.cli run EXEC --ros-args ... -- ARGS` in its own session
(process group), with the default SIGINT/SIGTERM dispositions whatever ours were. Its
stdout/stderr lines are copied to ours, prefixed with `[label] ` ([namespace/]name).

Respawn: a node (or container) with `respawn: true` that ends by itself while the launch runs is
started again after its `respawn_delay`, the others running on (launch's ExecuteProcess: any exit,
clean or not; with `on_exit: shutdown` as well ros2 launch would shut down instead, so the pair is
refused). Its end does not count in the exit status.

Stopping: on SIGINT/SIGTERM (a second one skips ahead), or as soon as a process without respawn
ends by itself, every process group gets SIGINT, then SIGTERM after the largest `sigterm_timeout`, then SIGKILL
after the largest `sigkill_timeout`; signals go to the whole group, so grandchildren stop too.
Exit status: 0 when the stop was requested and every node exited 0; otherwise non-zero (the
status of the node that ended by itself: its exit code, 128 + signal, or 1 when it exited 0; 1
when a node needed SIGTERM/SIGKILL or failed while stopping). Should the launcher itself be
killed, Linux sends each node SIGTERM (PR_SET_PDEATHSIG).
"""

from .frontend import (CONTAINER, PACKAGE, LaunchDescription, LaunchFileError, find_package_share, launch_file_path,
                       load_launch, node_command, parse_launch)
from .supervisor import DEFAULT_SIGINT_TIMEOUT, DEFAULT_SIGTERM_TIMEOUT, ChildSpec, Launcher

__all__ = ["CONTAINER", "PACKAGE", "LaunchDescription", "LaunchFileError", "find_package_share", "launch_file_path",
           "load_launch", "node_command", "parse_launch", "DEFAULT_SIGINT_TIMEOUT", "DEFAULT_SIGTERM_TIMEOUT",
           "ChildSpec", "Launcher"]
