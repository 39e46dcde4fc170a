"""The mismatch tool (issue 9): locate, name and model what the extended TD-SLIP model leaves out.

    from hopper_ros.diagnosis import diagnose_file
    result = diagnose_file("run.csv", output="out/")    # result["verdict"]
"""

from .api import diagnose_file  # noqa: F401
from .core import DiagnosisError, diagnose, load_settings  # noqa: F401
