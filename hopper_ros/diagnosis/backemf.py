"""The hip motor's current limited by its drive's voltage against the back-EMF (issue 28, point 3: a torque limit that
falls with the leg's speed): `laws.voltage_limited`, in stance

    tau in [-k V/R - (k^2/R) theta',  k V/R - (k^2/R) theta'],   k = G k_t (hardware.yaml's gear and torque constant),

V the voltage the drive can put across the winding, R the winding's resistance with its cables. A fixed saturation
(`torque_saturation`, the library's) clips the same torque at any speed; a viscous hip friction takes torque at any
command. Where the accepted effects leave the recording not explained (the stage of `unused.find_unused_law`, in its
round with the library's effects, those two among them): V searched at each R of a geometric grid
(`winding_resistances` from `winding_resistance_min` to `winding_resistance_max`), the R the held-out trajectories fit
best kept, then guarded and refitted like any effect. The search runs over the torque left at rest, k V/R, from
`stall_share` of the largest command to where the line no longer reaches any command (that command plus k^2/R times
the fastest sweep, `sweep_bound`: nothing changes there), the onset being sharp: a few volts more and no command is
clipped.
"""

from __future__ import annotations

import numpy as np

from .candidates import Candidate
from .simulate import Variant

NAME = "drive_voltage"
SITE = "stance_hip"
STALL_SHARE = 0.3      # the lowest torque at rest searched, a share of the largest command (`torque_saturation`'s)
REFINEMENTS = 3        # fine-grid passes: below its size the law clips every stride at once (the SSE's wall is a
                       #   volt wide where the first fine grid's step is one)


def sweep_bound(data) -> float:
    """[rad/s] the fastest sweep of the leg in stance on this recording, bounded above: the largest forward speed
    over the rest length less a fifth (the leg's shortest in stance)."""
    return float(np.max(np.abs(data.strides.forward_speed), initial=0.0)) / (0.8 * float(data.params.rest_length))


def motor_constant() -> float:
    """k = G k_t [N m/A] at the hip: hardware.yaml's motor gear ratio times its torque constant."""
    from hopper_ros.hardware.config import load_hardware
    motor = load_hardware().motor
    return float(motor.gear_ratio * motor.torque_constant)


def resistances(settings) -> np.ndarray:
    """The winding resistances tried [ohm] (geometric)."""
    return np.geomspace(settings.winding_resistance_min, settings.winding_resistance_max, settings.winding_resistances)


class BackEmf:
    """The drive's voltage limit at one winding resistance (the magnitude: V [V]; searched as k V/R [N m])."""

    def __init__(self, resistance: float, constant: float):
        self.resistance, self.constant = float(resistance), float(constant)

    def words(self, stall: float) -> str:
        """In the search's units: the torque left at rest, k V/R [N m]."""
        k, r = self.constant, self.resistance
        return (f"in stance, about the hip: the drive's voltage limits the motor's current against its back-EMF, "
                f"V = {stall * r / k:.3g} V over R = {r:.3g} ohm (k = G k_t = {k:.3g} N m/A): the torque left falls "
                f"with the leg's sweep, {stall:.3g} N m at rest and {k * k / r:.3g} N m less per rad/s of sweep (a "
                f"supply voltage too low for the speed; a torque limit that falls with speed, not a fixed saturation)")

    def terms(self) -> list:
        return [(f"clip(tau, -k V/R - k^2/R theta', k V/R - k^2/R theta'), R = {self.resistance:.3g} ohm", 1.0,
                 "the current a voltage V drives through the winding against the back-EMF", "V")]


def back_emf_candidate(resistance: float, constant: float, command_max: float, sweep_max: float) -> Candidate:
    """The law at winding resistance `resistance` [ohm], searched over the torque left at rest (k V/R) between
    STALL_SHARE of `command_max` [N m] and `command_max` + (k^2/R) `sweep_max` [rad/s], where it changes nothing."""
    found = BackEmf(resistance, constant)
    volts_per_newton_metre = resistance / constant
    high = command_max + constant * constant / resistance * sweep_max

    def build(variant: Variant, stall: float, r=found.resistance, k=found.constant) -> Variant:
        voltage = stall * volts_per_newton_metre if stall < high else 0.0
        return variant.with_changes(coefficients={NAME: voltage, "winding_resistance": r, "motor_constant": k})

    return Candidate(NAME, "physics", "actuator", SITE, "V", found.words(high), STALL_SHARE * command_max, high, build,
                     lambda stall: stall * volts_per_newton_metre,
                     "the leg swept by hand at several speeds against a fixed torque command (the torque left falls "
                     "with the speed for a voltage limit, not for a saturation)", origin=high, discovery=found,
                     refinements=REFINEMENTS,
                     equation="tau = clip(tau_cmd, -k V/R - (k^2/R) theta', k V/R - (k^2/R) theta') in stance")
