"""The search's interpolation of next-apex predictions between grid values (`fitting.interp_pred`): per stride,
`np.interp` over the grid values at which its lane did not fall, the same numbers bit for bit, taken for all strides
at once where every lane stands."""

import numpy as np

from hopper_ros.diagnosis.fitting import interp_pred


def per_stride(grid, pred_grid, values):
    out = {}
    for key, arr in pred_grid.items():
        col = np.empty(arr.shape[1])
        for i in range(arr.shape[1]):
            ok = np.isfinite(arr[:, i])
            col[i] = np.interp(values[i], grid[ok], arr[ok, i]) if ok.sum() >= 2 else np.nan
        out[key] = col
    return out


def test_interp_pred_gives_np_interps_numbers_per_stride():
    rng = np.random.default_rng(7)
    for trial in range(400):
        size = int(rng.integers(2, 9))
        grid = (np.linspace(rng.uniform(-1.0, 0.0), rng.uniform(0.1, 2.0), size) if trial % 2
                else np.sort(rng.uniform(-1.0, 3.0, size)))
        strides = 50
        pred = {key: rng.normal(size=(size, strides)) * 10.0 ** rng.uniform(-6, 3) for key in ("height", "speed")}
        pred["height"][rng.integers(0, size, 6), rng.integers(0, strides, 6)] = np.nan    # lanes that fell
        pred["speed"][:, 3] = np.nan                                                         # a stride that always did
        values = rng.uniform(grid[0] - 0.3, grid[-1] + 0.3, strides)                       # beyond both ends too
        on_point = rng.random(strides) < 0.2
        values[on_point] = grid[rng.integers(0, size, on_point.sum())]
        values[:2] = grid[0], grid[-1]
        expected, got = per_stride(grid, pred, values), interp_pred(grid, pred, values)
        for key in pred:
            assert np.array_equal(got[key], expected[key], equal_nan=True), (trial, key)
