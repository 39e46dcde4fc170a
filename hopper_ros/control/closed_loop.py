"""Fig 5.3 at an apex: the deadbeat controller's two stages driving the stride machine.

Shared by the deadbeat_controller node and the in-process graph (`harness.graph_lockstep`), so the
closed loop they run is one piece of code.
"""

from __future__ import annotations

from .deadbeat import DeadbeatController, StrideDecision
from .stride_machine import StrideMachine, StridePlan


def plan_of(decision: StrideDecision) -> StridePlan:
    return StridePlan(decision.tau_0, decision.touchdown_angle, decision.ramp_duration)


def decide_at_apex(controller: DeadbeatController, machine: StrideMachine, apex_height: float, forward_speed: float,
                   setpoint: tuple[float, float], stride_index: int) -> StrideDecision:
    """Stage 1 moves the leg at once (an infeasible stride: leg held, no torque); stage 2, about a
    millisecond later, revises the stride's plan. Returns the decision the stride runs on."""
    first = controller.first_decision(apex_height, forward_speed, *setpoint, stride_index)
    if first.feasible:
        machine.on_apex(plan_of(first), first.reason)
    else:
        machine.on_apex(None, first.reason)
        machine.hold_angle = first.touchdown_angle
    decision = controller.refine(first, apex_height, forward_speed)
    if decision is not first and decision.feasible:
        machine.revise(plan_of(decision))
    return decision
