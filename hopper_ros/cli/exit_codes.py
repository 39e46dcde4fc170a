"""Exit statuses of every `hopper` command and every node (README.md, "Exit codes").

    0  OK         done
    1  FAILURE    ran, but did not succeed: a node died, nothing arrived within --timeout, a bag could not
                  be written, the demo's loop failed
    2  USAGE      the command line (or the environment) is wrong: argparse's own errors, an unknown node or
                  option value combination, an invalid ROS_AUTOMATIC_DISCOVERY_RANGE
    3  BAD_INPUT  a file, recording, configuration, mapping or value the tool cannot use; one line on
                  stderr names it, the key or field, and what is wrong
"""

OK = 0
FAILURE = 1
USAGE = 2
BAD_INPUT = 3
