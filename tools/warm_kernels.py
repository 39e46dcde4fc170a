"""`make setup`'s last step: every numba kernel of the package loaded from, or compiled into, the disk cache
(`hopper_ros.physics.compiled.cache_directory`) once, before anything uses it.

Without it each process that first needs a kernel compiles it: on a fresh machine the three sessions of `make
test` and every simulated robot the node tests start compiled the same kernels side by side (about 40 s of one
core each for the lanes and the diagnosis's trajectory error). Each kernel is called here once with the argument
types the package passes (numba keeps one compiled version per type signature).
"""

import sys
import time

import numpy as np


def main() -> int:
    started = time.monotonic()
    try:
        from hopper_ros.physics.lanes import compiled_backend
    except ImportError as exc:
        print(f"setup: kernels not compiled ahead: {exc}", file=sys.stderr)
        return 0
    if compiled_backend() is None:
        return 0           # numba absent or HOPPER_LANES=numpy: the numpy paths compile nothing
    from hopper_ros.diagnosis.compiled import _sse
    from hopper_ros.physics import laws
    from hopper_ros.physics.lanes import simulate_lanes
    from hopper_ros.sim.plant import kernel

    lanes = simulate_lanes(laws.Coefficients(), [0.5], [1.0], [0.1], [0.0], [0.05], duration=0.05,
                           needed=np.array([2]))
    strides = np.array([[0], [2]], dtype=np.int64)
    t, stance, since = np.array([0.0, 1e-3]), np.array([False, True]), np.array([-1.0, -1.0])
    measured = np.zeros((3, 2))
    sensors = np.zeros((3, 3, 1))
    sensors[:, 1] = 1.0
    one = np.zeros(1)
    _sse(lanes.y, lanes.z, lanes.theta, strides, t, measured, one, one, one, stance, since, np.ones(3), sensors,
         np.zeros((3, 4, 1)), 1, np.empty((1, 1)))
    kernel()
    print(f"setup: numba kernels ready in the disk cache ({time.monotonic() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
