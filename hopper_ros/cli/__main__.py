"""`python -m hopper_ros.cli ...` is the `hopper` command."""

import sys

from hopper_ros.cli import main

sys.exit(main())
