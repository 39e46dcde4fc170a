"""Transitional alias of `hopper_ros.harness.collect` (issue 18 moved the harnesses to
harness/). Kept only for bench/diagnosis_sim_sweep.py (and so test/test_diagnosis.py), which a
parallel branch edits; delete once it imports hopper_ros.harness.collect. Nothing else may use it:
a library package does not import the harnesses."""
import sys

from hopper_ros.harness import collect as _collect

sys.modules[__name__] = _collect
