"""The three sensing stages chained in one process: packet -> sample -> estimates -> events.

What the three nodes do across topics, without ROS: for tests, benchmarks and offline replays
of recorded packet streams.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hopper_ros.hardware.config import HardwareConfig, load_hardware
from hopper_ros.physics.params import ModelParams

from .bridge import BridgeSample, EncoderBridge
from .config import SensingConfig, load_sensing_config
from .estimator import StateEstimator
from .events import EventDetector
from .samples import DetectedEvent, Estimate


@dataclass
class PipelineOutput:
    sample: BridgeSample | None
    estimates: list[Estimate] = field(default_factory=list)
    events: list[DetectedEvent] = field(default_factory=list)


class SensingPipeline:
    def __init__(self, config: SensingConfig, hardware: HardwareConfig, params: ModelParams) -> None:
        self.bridge = EncoderBridge.from_config(hardware, config.bridge)
        self.estimator = StateEstimator.from_config(config.estimator, hardware)
        self.detector = EventDetector(params, config.detector)

    @classmethod
    def from_files(cls, sensing_file: str = "sensing.yaml", hardware: HardwareConfig | None = None,
                   model_file: str | None = None) -> "SensingPipeline":
        from hopper_ros.config.schemas import load_model

        config = load_sensing_config(sensing_file)
        return cls(config, hardware if hardware is not None else load_hardware(config.hardware_file),
                   load_model(model_file or config.model_file))

    def process(self, datagram: bytes, receive_time: float) -> PipelineOutput:
        sample = self.bridge.process(datagram, receive_time)
        output = PipelineOutput(sample)
        if sample is None:
            return output
        output.estimates = self.estimator.update(sample.measurement())
        for estimate in output.estimates:
            output.events.extend(self.detector.update(estimate))
        return output
