"""The numerics of a candidate's fit: a magnitude on a grid, with the accepted effects (its partners) refitted
by a quadratic about their values at each grid value (backfitting), the SSE profile's vertex, and values
interpolated between grid points."""

from __future__ import annotations

import numpy as np


def partner_points(r) -> tuple[np.ndarray, int, float, float]:
    """Three magnitudes of an accepted effect (`records.Scored`) to refit it at (its value and one either side,
    inside its bounds), the index of its value among them, and the range its refit may move over."""
    c, v = r.candidate, float(r.value)
    span = c.high - c.low
    step = max(0.5 * abs(v - c.origin), 0.02 * span)
    below, above = min(step, v - c.low), min(step, c.high - v)
    if below <= 1e-9 * span:
        xs, centre = np.array([v, v + above, v + 2 * above]), 0
    elif above <= 1e-9 * span:
        xs, centre = np.array([v - 2 * below, v - below, v]), 2
    else:
        xs, centre = np.array([v - below, v, v + above]), 1
    width = xs[2] - xs[0]
    return xs, centre, max(c.low, xs[0] - 0.5 * width), min(c.high, xs[2] + 0.5 * width)


def newton(xs: np.ndarray, ys: list, x):
    """The quadratic through (xs[j], ys[j]) at x (arrays broadcast)."""
    d1 = (ys[1] - ys[0]) / (xs[1] - xs[0])
    d2 = ((ys[2] - ys[1]) / (xs[2] - xs[1]) - d1) / (xs[2] - xs[0])
    return ys[0] + d1 * (x - xs[0]) + d2 * (x - xs[0]) * (x - xs[1])


def quadratic_min(xs: np.ndarray, ys: list, low: float, high: float) -> np.ndarray:
    """Per column, where the quadratic through the three points is lowest within [low, high]."""
    d1 = (ys[1] - ys[0]) / (xs[1] - xs[0])
    d2 = ((ys[2] - ys[1]) / (xs[2] - xs[1]) - d1) / (xs[2] - xs[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(d2 > 0, (xs[0] + xs[1]) / 2 - d1 / np.where(d2 > 0, 2 * d2, 1.0), low)
    tries = np.stack([np.clip(vertex, low, high), np.full_like(vertex, low), np.full_like(vertex, high),
                      np.full_like(vertex, xs[0]), np.full_like(vertex, xs[1]), np.full_like(vertex, xs[2])])
    values = newton(xs, ys, tries)
    return np.take_along_axis(tries, np.argmin(values, axis=0)[None], 0)[0]


class Backfit:
    """A candidate's (partner point, grid value, stride) block: the partners refitted per grid value."""

    def __init__(self, sse: np.ndarray, pred: dict, points: list):
        self.sse, self.pred, self.points = sse, pred, points

    def _ys(self, block: np.ndarray, i: int, columns) -> list:
        xs, centre, _, _ = self.points[i]
        others = iter((1 + 2 * i, 2 + 2 * i))
        return [block[0][:, columns] if j == centre else block[next(others)][:, columns] for j in range(3)]

    def partner_values(self, columns) -> list:
        """Per partner, its magnitude at every grid value (on these strides' summed SSE): the one partner
        whose refit gains most is refitted, the others stay (partners that look alike would otherwise
        each take the whole correction); `_polish` repeats the fit from the new magnitudes."""
        total = self.sse[:, :, columns].sum(axis=2)[:, :, None]
        moves, gains = [], []
        for i, p in enumerate(self.points):
            ys = self._ys(total, i, [0])
            x = quadratic_min(p[0], ys, p[2], p[3])[:, 0]
            moves.append(x)
            gains.append(newton(p[0], ys, x[:, None])[:, 0] - total[0, :, 0])
        if len(moves) > 1:
            best = np.argmin(np.array(gains), axis=0)
            moves = [np.where(best == i, x, p[0][p[1]]) for i, (x, p) in enumerate(zip(moves, self.points))]
        return moves

    def at(self, block: np.ndarray, partner: list, columns) -> np.ndarray:
        """(grid, strides) of `block` with the partners at `partner` (per grid value), additive in partners."""
        out = block[0][:, columns].copy()
        for i, x in enumerate(partner):
            out += newton(self.points[i][0], self._ys(block, i, columns), x[:, None]) - block[0][:, columns]
        return out


def vertex(grid: np.ndarray, values: np.ndarray) -> float:
    """Where a sampled SSE is lowest: the vertex of the parabola through the best grid point and its neighbours
    (an SSE is quadratic in a magnitude near its minimum; its logarithm is not)."""
    k = int(np.argmin(values))
    j = min(max(k, 1), len(grid) - 2)
    xs, ys = grid[j - 1:j + 2], values[j - 1:j + 2]
    d1 = (ys[1] - ys[0]) / (xs[1] - xs[0])           # divided differences, as `newton`
    d2 = ((ys[2] - ys[1]) / (xs[2] - xs[1]) - d1) / (xs[2] - xs[0])
    if d2 <= 0:
        return float(grid[k])
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    return float(np.clip((xs[0] + xs[1]) / 2 - d1 / (2 * d2), lo, hi))


def quadratic_at(grid: np.ndarray, values: np.ndarray, x: float) -> np.ndarray:
    """Columns of `values` (grid x columns) interpolated at x through the three nearest grid points."""
    k = int(np.clip(np.searchsorted(grid, x), 1, len(grid) - 2))
    xs = grid[k - 1:k + 2]
    out = 0.0
    for j in range(3):
        others = [xs[i] for i in range(3) if i != j]
        out = out + values[k - 1 + j] * ((x - others[0]) * (x - others[1]) / ((xs[j] - others[0]) * (xs[j] - others[1])))
    return out


def interp_pred(grid, pred_grid: dict, values: np.ndarray) -> dict:
    """Next-apex predictions per stride at per-stride magnitudes, interpolated on the grid (an increasing one):
    `np.interp` per stride over its finite grid points, the same numbers; strides whose every grid point is finite
    (nearly all) at once, with np.interp's own arithmetic."""
    grid, values = np.asarray(grid, dtype=float), np.asarray(values, dtype=float)
    last = len(grid) - 1
    j = np.clip(np.searchsorted(grid, values, side="right") - 1, 0, max(last - 1, 0))   # grid[j] <= x < grid[j+1]
    x0, x1 = grid[j], grid[np.minimum(j + 1, last)]
    columns = np.arange(len(values))
    out = {}
    for key, arr in pred_grid.items():       # arr: (grid, strides)
        y0, y1 = arr[j, columns], arr[np.minimum(j + 1, last), columns]
        with np.errstate(divide="ignore", invalid="ignore"):
            col = (y1 - y0) / (x1 - x0) * (values - x0) + y0
        col = np.where(values == x0, y0, col)                       # on a grid point: its value
        col = np.where(values >= grid[-1], arr[-1], np.where(values < grid[0], arr[0], col))   # beyond: the end's
        finite = np.isfinite(arr).all(axis=0) & np.isfinite(values) & np.isfinite(col) & (last >= 1)
        for i in np.flatnonzero(~finite):   # a stride whose lane fell at some grid value: its finite points only
            ok = np.isfinite(arr[:, i])
            col[i] = np.interp(values[i], grid[ok], arr[ok, i]) if ok.sum() >= 2 else np.nan
        out[key] = col
    return out
