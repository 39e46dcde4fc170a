"""The leg angle's stage (`diagnosis.angle`) forced on the plain model of every recording given: what it would say
with no accepted effect, explained or not (the no-false-alarm check of docs/diagnosis.md, "Measured").

    python bench/angle_forced.py RECORDING.csv ...
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from hopper_ros.diagnosis.angle import on_plain_model
from hopper_ros.diagnosis.settings import load_settings
from hopper_ros.physics.params import load_model
from hopper_ros.recording.recordings import load_recording


def main(paths: list[str]) -> None:
    settings, (params, _) = load_settings("diagnosis.yaml"), load_model("model.yaml")
    for path in paths:
        started = time.time()
        try:
            r = on_plain_model(load_recording(path), params, settings)
            said = "nothing" if r is None else (f"{r.name} = {r.magnitude:.4g} {r.candidate.unit} (t {r.t:.1f}, "
                                                f"held-out reduction {r.reduction:.3f}): {r.candidate.describe(r.value)}")
        except Exception as error:          # a recording the tool cannot diagnose: said, the others go on
            said = f"error {type(error).__name__}: {error}"
        print(f"{Path(path).parent.name}/{Path(path).stem}: {said} [{time.time() - started:.0f} s]", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
