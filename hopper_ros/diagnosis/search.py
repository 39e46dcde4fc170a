"""The search on one recording: candidates gridded, fitted per fold and scored on held-out strides.

A `Search` holds what every step of it shares (the prepared recording, the base variant, the settings,
the folds, the progress). Candidates are searched on top of a `Stack` (the base and the effects accepted
so far, refitted with every new candidate: backfitting, `fitting.Backfit`), first on a coarse grid, then
on a fine one about the best value; the best are scored again from strides simulated at their fold
magnitudes (no interpolation). `screen` keeps the candidates worth that, from a subset of the strides.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from . import acceptance
from .candidates import Candidate, search_grid
from .data import StrideData
from .fitting import Backfit, interp_pred, partner_points, quadratic_at, vertex
from .progress import QUIET, Progress
from .records import Errors, Fit, Reference, Scored
from .settings import Settings
from .simulate import Variant, simulate_variants
from .sites import first_sites


@dataclass
class Stack:
    """The model a round searches on top of: the base variant and the effects accepted so far, whose
    magnitudes are refitted with every new candidate (backfitting: a first effect fitted alone absorbs
    part of a second one's signature)."""
    base: Variant
    effects: list

    def variant(self, values=None) -> Variant:
        v = self.base
        for k, r in enumerate(self.effects):
            v = r.candidate.build(v, float(r.value if values is None else values[k]))
        return v


def folds(n: int, k: int) -> np.ndarray:
    """The fold of each of n strides (round robin over k folds, at least 2)."""
    return np.arange(n) % max(2, min(k, n))


class Search:
    def __init__(self, data: StrideData, base: Variant, settings: Settings, progress: Progress = QUIET) -> None:
        self.data, self.base, self.settings, self.progress = data, base, settings, progress
        self.fold = folds(len(data.strides), settings.folds)

    def stack(self, effects: list) -> Stack:
        return Stack(self.base, list(effects))

    def reference(self, stack: Stack) -> Reference:
        """Per-stride trajectory SSE and the next-apex errors of the model `stack` (what additions are judged
        against)."""
        sim = simulate_variants(self.data, [stack.variant()])
        return Reference(sim["sse"][0], Errors.of(self.data, {k: v[0] for k, v in sim["pred"].items()}))

    def held_out(self, chosen: list[Scored]) -> Reference:
        """Per stride, the trajectory SSE and the next apex's errors with the chosen effects at the magnitudes
        fitted without the stride's fold."""
        sse, pred = self._held_out(chosen)
        return Reference(sse, Errors.of(self.data, pred))

    def _held_out(self, chosen: list[Scored]) -> tuple[np.ndarray, dict]:
        fold = self.fold
        numbers = list(np.unique(fold))
        variants = []
        for fi in range(len(numbers)):
            v = self.base
            for r in chosen:
                v = r.candidate.build(v, float(r.fit.fold_values[fi]))
            variants.append(v)
        sim = simulate_variants(self.data, variants)
        rows, cols = np.array([numbers.index(f) for f in fold]), np.arange(len(fold))
        return sim["sse"][rows, cols], {k: sim["pred"][k][rows, cols] for k in sim["pred"]}

    def cumulative_errors(self, chosen: list[Scored]) -> list[Errors]:
        """Held-out E_p/E_v/E_t after each accepted effect and those before it, at their final magnitudes."""
        return [self.held_out(chosen[:k]).errors for k in range(1, len(chosen) + 1)]

    # ---------------------------------------------------------------- ranking

    def rank(self, stack: Stack, candidates: list[Candidate], reference: Reference,
             grids: dict | None = None, label: str = "") -> list[Scored]:
        """Grid each candidate's magnitude on top of `stack` (its accepted effects refitted at each grid value),
        fit it per fold on the training strides, score it on the held-out ones. Best first."""
        if not candidates:
            return []
        settings, data = self.settings, self.data
        grids = grids or {c.name: search_grid(c, settings.grid) for c in candidates}
        points = [partner_points(r) for r in stack.effects]
        partner_rows = [None]
        for i, (xs, centre, _, _) in enumerate(points):
            for j in range(3):
                if j != centre:
                    values = [float(r.value) for r in stack.effects]
                    values[i] = float(xs[j])
                    partner_rows.append(values)
        bases = [stack.variant(values) for values in partner_rows]
        n = len(data.strides)
        results = []
        with self.progress.bar(len(candidates), label or self.progress.stage) as step:
            for c in candidates:
                grid = grids[c.name]
                sim = simulate_variants(data, [c.build(b, float(v)) for b in bases for v in grid])
                fit = Backfit(sim["sse"].reshape(len(bases), len(grid), n),
                              {k: v.reshape(len(bases), len(grid), n) for k, v in sim["pred"].items()}, points)
                results.append(self._fitted(c, grid, fit, points, reference))
                step(c.name)
        results.sort(key=lambda r: -r.reduction)
        return results

    def _fitted(self, c: Candidate, grid: np.ndarray, fit: Backfit, points: list, reference: Reference) -> Scored:
        fold = self.fold
        n = len(fold)
        everything = np.arange(n)
        partner_all = fit.partner_values(everything)
        profile_all = fit.at(fit.sse, partner_all, everything).sum(axis=1)
        floor = 0.5 * fit.sse[0].min(axis=0)
        held, held_values = np.empty(n), np.empty(n)
        pred_held = {k: np.empty((len(grid), n)) for k in fit.pred}
        fold_values, partner_folds = [], [[] for _ in points]
        for f in np.unique(fold):
            train, test = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
            partner = fit.partner_values(train)
            m = vertex(grid, fit.at(fit.sse, partner, train).sum(axis=1))
            fold_values.append(m)
            for i, x in enumerate(partner):
                partner_folds[i].append(float(np.interp(m, grid, x)))
            held[test] = np.maximum(quadratic_at(grid, fit.at(fit.sse, partner, test), m), floor[test])
            held_values[test] = m
            for k, block in fit.pred.items():
                pred_held[k][:, test] = fit.at(block, partner, test)
        value = vertex(grid, profile_all)
        fit_total = float(quadratic_at(grid, profile_all[:, None], value)[0])
        errors = Errors.of(self.data, interp_pred(grid, pred_held, held_values))
        base_total = reference.sse.sum()
        scored = Scored(c, Fit(value, fold_values, [float(np.interp(value, grid, x)) for x in partner_all],
                               partner_folds, grid, float(1.0 - max(fit_total, 0.0) / base_total),
                               float(1.0 - profile_all.min() / base_total)),
                        c.physical(value), held, errors)
        return acceptance.score(scored, self.data, reference, self.settings)

    def search(self, stack: Stack, candidates: list[Candidate], reference: Reference) -> list[Scored]:
        """`rank`, then `refine`."""
        return self.refine(stack, self.rank(stack, candidates, reference), reference)

    def refine(self, stack: Stack, ranking: list[Scored], reference: Reference, exact: int = 12) -> list[Scored]:
        """Every candidate again on a fine grid between the neighbours of its best grid value (an SSE is not
        parabolic where an effect switches on, e.g. a torque limit; a candidate with `refinements` n > 1 n times,
        each grid finer), then the best scored from strides simulated at their fold magnitudes (no interpolation)."""
        ranking = self._finer(stack, ranking, reference, ranking)
        for passes in range(1, max((r.candidate.refinements for r in ranking), default=1)):
            ranking = self._finer(stack, ranking, reference, [r for r in ranking if r.candidate.refinements > passes])
        ranking.sort(key=lambda r: -r.fit.fit_reduction)
        best = ranking[:exact] + [r for r in ranking[exact:] if r.candidate.kind == "discovered"]
        self.evaluate_exactly(stack, best, reference)
        ranking.sort(key=lambda r: -r.reduction)
        return ranking

    def _finer(self, stack: Stack, ranking: list[Scored], reference: Reference, these: list[Scored]) -> list[Scored]:
        """`ranking` with each of `these` searched again on a fine grid between the neighbours of its best grid value,
        where that fits better."""
        grids = {}
        for r in these:
            grid = r.fit.grid
            k = int(np.argmin(np.abs(grid - r.value)))
            grids[r.name] = np.linspace(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)], self.settings.grid)
        refined = {r.name: r for r in self.rank(stack, [r.candidate for r in these], reference, grids=grids,
                                                label=f"{self.progress.stage} (fine grid)")}
        return [refined[r.name] if r.name in refined and refined[r.name].fit.fit_reduction > r.fit.fit_reduction
                else r for r in ranking]

    def evaluate_exactly(self, stack: Stack, results: list[Scored], reference: Reference) -> None:
        """Held-out scores of fitted candidates from strides simulated at their fold magnitudes."""
        fold = self.fold
        numbers = list(np.unique(fold))
        variants = [r.candidate.build(stack.variant([p[fi] for p in r.fit.partner_fold_values]), float(v))
                    for r in results for fi, v in enumerate(r.fit.fold_values)]
        sim = simulate_variants(self.data, variants)
        idx = np.array([numbers.index(f) for f in fold])
        cols = np.arange(len(fold))
        for k, r in enumerate(results):
            rows = k * len(numbers) + idx
            r.held_sse = sim["sse"][rows, cols]
            r.errors = Errors.of(self.data, {key: v[rows, cols] for key, v in sim["pred"].items()})
            acceptance.score(r, self.data, reference, self.settings)

    def screen(self, stack: Stack, candidates: list[Candidate], located: set) -> list[Candidate]:
        """The candidates worth a full search: the best by trajectory reduction on a subset of strides
        (coarse grid), plus every candidate acting where locate sees a residual."""
        settings = self.settings
        n = len(self.data.strides)
        if len(candidates) <= settings.screen:
            return candidates
        index = np.linspace(0, n - 1, min(n, settings.screen_strides)).round().astype(int)
        subsets = self.data.subsets     # a later screen on the same strides finds the variants simulated
        if tuple(index) not in subsets:
            subsets[tuple(index)] = dataclasses.replace(self.data, strides=self.data.strides.subset(index))
        subset = Search(subsets[tuple(index)], self.base, dataclasses.replace(settings, grid=5), self.progress)
        ranked = subset.rank(stack, candidates, subset.reference(stack))
        # the best grid point counts too: an SSE that is not parabolic in the magnitude (a torque limit) has a
        # vertex far from its minimum on a coarse grid
        ranked.sort(key=lambda r: -max(r.fit.fit_reduction, r.fit.grid_reduction))
        keep = {r.name for r in ranked[:settings.screen]}
        keep |= {c.name for c in candidates if c.kind != "sensor" and set(first_sites(c.site)) & located
                 and any(r.name == c.name and r.reduction > 0 for r in ranked)}
        return [c for c in candidates if c.name in keep]

    # ---------------------------------------------------------------- refits beside accepted effects

    def polish(self, partners: list[Scored], result: Scored, reference: Reference) -> Scored:
        """The joint fit of `result` with its partners, repeated from the refitted magnitudes: each pass refits
        the partners by a quadratic about their values, exact once the magnitudes stop moving."""
        stack = self.stack(partners)
        for _ in range(self.settings.polish if partners else 0):
            adopt(partners, result)
            step = np.diff(result.fit.grid).max()
            grid = {result.name: np.linspace(result.value - step, result.value + step, self.settings.grid)}
            again = self.rank(stack, [result.candidate], reference, grids=grid)
            self.evaluate_exactly(stack, again, reference)
            moved = [abs(a - b) for a, b in zip(again[0].fit.partner_values, [r.value for r in partners])]
            if again[0].reduction < result.reduction:
                break
            result.adopt(again[0])
            if all(m <= 1e-3 * (r.candidate.high - r.candidate.low) for m, r in zip(moved, partners)):
                break
        adopt(partners, result)
        return result


JOINT_START = 0.3      # the joint refit's first step: this share of each magnitude (of its search range at 0)
JOINT_STEPS = 16       # ... patterns tried at most


def refit_jointly(search: Search, chosen: list[Scored]) -> bool:
    """The magnitudes of `chosen` (two or more, each found beside the others one at a time) fitted together: a
    pattern search over every combination of -step, 0, +step per magnitude (3^n variants, one simulation), moving
    to the best and halving the steps where the centre stays best; then per fold the minimum of a quadratic fitted
    to its training strides' SSE over the last pattern. Two laws whose magnitudes trade against each other (plant C's
    round toe and the drive's voltage limit: each fitted beside the other stopped 30 % and 20 % off, the next apex at
    15 x its noise floor, at their true values on it) sit in a narrow valley that refits one at a time cross in
    zig-zags. The effects `move_to` the fit where it lowers the SSE over all strides; returns whether it did."""
    n = len(chosen)
    if n < 2:
        return False
    data, fold = search.data, search.fold
    low = np.array([r.candidate.low for r in chosen])
    high = np.array([r.candidate.high for r in chosen])
    centre = np.array([float(r.value) for r in chosen])
    step = np.where(centre != 0.0, JOINT_START * np.abs(centre), JOINT_START * (high - low))
    offsets = np.array(np.meshgrid(*[(-1.0, 0.0, 1.0)] * n, indexing="ij")).reshape(n, -1).T     # 3^n x n
    middle = int(np.flatnonzero(~offsets.any(axis=1))[0])

    def pattern(centre, step):
        points = np.clip(centre + offsets * step, low, high)
        variants = []
        for x in points:
            v = search.base
            for r, value in zip(chosen, x):
                v = r.candidate.build(v, float(value))
            variants.append(v)
        return points, simulate_variants(data, variants)["sse"]      # (3^n, n) and (3^n, strides)

    points, sse = pattern(centre, step)
    start = float(sse[middle].sum())
    for _ in range(JOINT_STEPS):
        best = int(np.argmin(sse.sum(axis=1)))
        if best == middle:
            step = step / 2.0
        centre = points[best]
        points, sse = pattern(centre, step)
    if not sse[middle].sum() < start:
        return False
    # per fold: the quadratic in the magnitudes (scaled by the step) that fits its training strides' SSE best
    u = (points - centre) / np.where(step > 0, step, 1.0)
    columns = [np.ones(len(u))] + [u[:, i] for i in range(n)] + [u[:, i] * u[:, j] for i in range(n) for j in range(i, n)]
    design = np.column_stack(columns)
    fold_values = []
    for f in np.unique(fold):
        total = sse[:, fold != f].sum(axis=1)
        coef = np.linalg.lstsq(design, total, rcond=None)[0]
        g, hessian = coef[1:n + 1], np.zeros((n, n))
        k = n + 1
        for i in range(n):
            for j in range(i, n):
                hessian[i, j] += coef[k] * (2.0 if i == j else 1.0)
                hessian[j, i] = hessian[i, j]
                k += 1
        try:
            vertex_u = np.linalg.solve(hessian, -g)
        except np.linalg.LinAlgError:
            vertex_u = None
        if vertex_u is None or np.any(np.linalg.eigvalsh(hessian) <= 0) or np.any(np.abs(vertex_u) > 1.0):
            vertex_u = u[int(np.argmin(total))]          # no minimum inside the pattern: its best point
        fold_values.append(np.clip(centre + vertex_u * step, low, high))
    for i, r in enumerate(chosen):
        r.move_to(float(centre[i]), [float(v[i]) for v in fold_values])
    return True


def adopt(chosen: list[Scored], result: Scored) -> None:
    """The accepted effects take the magnitudes they were refitted to beside `result`."""
    for r, value, fold_values in zip(chosen, result.fit.partner_values, result.fit.partner_fold_values):
        r.move_to(value, fold_values)
