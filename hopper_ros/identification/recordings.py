"""Transitional alias of `hopper_ros.recording.recordings` (issue 18 moved the recording data
model to recording/). Kept only for diagnosis/, bench/diagnosis_sim_sweep.py and the diagnosis
tests, which a parallel branch edits; delete once they import hopper_ros.recording.recordings."""
import sys

from hopper_ros.recording import recordings as _recordings

sys.modules[__name__] = _recordings
