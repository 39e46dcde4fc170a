"""Online check of a stride predictor: pairs each stride's opening apex with its command,
predicts the next apex, and scores the prediction with E_p, E_v, E_t (4.1)-(4.3) when that
apex arrives. No ROS import; `nodes/stride_predictor.py` connects it to topics.

Stride n opens at the apex with stride_index n; its command carries stride_index n; the
apex it predicts carries stride_index n + 1. Positions and times of the prediction are
absolute (the opening apex's y and t plus the predicted stride length and time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopper_ros.physics.metrics import position_error_pct, time_error_pct, velocity_error_pct
from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import DEFAULT_PREDICTOR, PREDICTORS, predict_stride


@dataclass(frozen=True)
class Apex:
    stride_index: int
    time: float            # [s]
    y: float               # [m]
    apex_height: float     # [m]
    forward_speed: float   # [m/s]


@dataclass(frozen=True)
class Command:
    stride_index: int
    tau_0: float                    # [N m]
    touchdown_angle: float          # [rad]
    ramp_duration: float | None     # [s]; None: the predictor's own lift-off time


@dataclass(frozen=True)
class Prediction:
    """The predicted apex `stride_index` (or why the stride is predicted to fail)."""

    stride_index: int
    ok: bool
    failure: str
    time: float = float("nan")
    y: float = float("nan")
    apex_height: float = float("nan")
    forward_speed: float = float("nan")


@dataclass(frozen=True)
class Score:
    stride_index: int
    position_error_pct: float
    velocity_error_pct: float
    time_error_pct: float


class StrideMonitor:
    """Predicts each stride from its apex and command; scores predictions as apexes arrive."""

    def __init__(self, params: ModelParams, method: str = DEFAULT_PREDICTOR, keep: int = 16):
        if method not in PREDICTORS:
            raise ValueError(f"unknown predictor {method!r}; choose one of {PREDICTORS}")
        self.params, self.method, self._keep = params, method, keep
        self._apexes: dict[int, Apex] = {}
        self._commands: dict[int, Command] = {}
        self._predictions: dict[int, Prediction] = {}
        self.scores: list[Score] = []
        self.predicted = 0
        self.infeasible = 0

    def on_apex(self, apex: Apex) -> tuple[Score | None, Prediction | None]:
        """Score the prediction of this apex, if any; predict its stride if commanded."""
        score = None
        predicted = self._predictions.pop(apex.stride_index, None)
        opening = self._apexes.get(apex.stride_index - 1)
        if predicted is not None and predicted.ok and opening is not None:
            score = Score(
                apex.stride_index,
                float(position_error_pct(apex.apex_height, apex.y - opening.y, predicted.apex_height, predicted.y - opening.y)),
                float(velocity_error_pct(apex.forward_speed, predicted.forward_speed)),
                float(time_error_pct(apex.time - opening.time, predicted.time - opening.time)),
            )
            self.scores.append(score)
        self._apexes[apex.stride_index] = apex
        self._forget(apex.stride_index)
        return score, self._predict(apex.stride_index)

    def on_command(self, command: Command) -> Prediction | None:
        self._commands[command.stride_index] = command
        return self._predict(command.stride_index)

    def mean_errors(self) -> tuple[float, float, float]:
        if not self.scores:
            return (float("nan"),) * 3
        values = np.array([(s.position_error_pct, s.velocity_error_pct, s.time_error_pct) for s in self.scores])
        return tuple(float(v) for v in values.mean(axis=0))

    def _predict(self, stride_index: int) -> Prediction | None:
        apex, command = self._apexes.get(stride_index), self._commands.get(stride_index)
        if apex is None or command is None or stride_index + 1 in self._predictions:
            return None
        p = predict_stride(self.params, apex.apex_height, apex.forward_speed, command.touchdown_angle,
                           command.tau_0, command.ramp_duration, method=self.method)
        self.predicted += 1
        if not p.ok:
            self.infeasible += 1
            prediction = Prediction(stride_index + 1, False, p.failure)
        else:
            prediction = Prediction(stride_index + 1, True, "", apex.time + p.stride_time, apex.y + p.stride_length,
                                    p.next_apex_height, p.next_forward_speed)
        self._predictions[stride_index + 1] = prediction
        return prediction

    def _forget(self, newest: int) -> None:
        for table in (self._apexes, self._commands, self._predictions):
            for index in [i for i in table if i < newest - self._keep]:
                del table[index]
