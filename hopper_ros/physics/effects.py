"""The effect library: physics the extended TD-SLIP model may lack, and sensor faults, by family.

Each entry says where it acts (`site`), its law (the equation, with the seed's number where it has
one; derivations in docs/diagnosis.md), its parameters with SI units and bounds, and what it means in
a researcher's words. An entry only sets coefficients of `hopper_ros.physics.laws`, where every law
is written once, so the simulated robot (config/sim.yaml `effects:`), identification
(`hopper identify --effects`) and the mismatch tool (`hopper diagnose`) share it.

Families: flight resistance, the boom, touchdown, the ground, the leg in stance, the hip actuator,
the lift-off collision, sensors. A magnitude of an entry is its first parameter's value; further
parameters are secondary (fitted once the entry is accepted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

SITES = ("flight", "touchdown", "stance_leg", "stance_hip", "actuator", "liftoff", "sensor")


@dataclass(frozen=True)
class Parameter:
    name: str
    unit: str
    low: float              # bounds of the search (absolute, or factors of the model's value when `relative`)
    high: float
    coefficient: str        # the `laws.Coefficients` field (or sensor key) it sets
    relative: bool = False  # bounds are factors of the model's own coefficient
    inverse: bool = False   # searched as 1/value (a limit or a stiffness whose "off" is infinity)
    plausible: tuple = (0.0, math.inf)   # |value - off| a real sensor could have and the data resolve (sensor guard)
    # (quantity, low, high): where a recording resolves it, as factors of a quantity the recording excites
    # (a torque limit only shows between the smallest and largest commanded torques); see `data_bounds`
    resolved: tuple = ()


@dataclass(frozen=True)
class Effect:
    name: str
    family: str
    site: str
    direction: str          # horizontal | vertical | both | along | across | hip | channel name
    parameters: tuple
    equation: str
    words: str
    separate: str           # the experiment that makes it stand out from look-alikes
    kind: str = "physics"   # physics | sensor
    fixed: dict = field(default_factory=dict)   # other coefficients it sets to fixed values when on

    @property
    def primary(self) -> Parameter:
        return self.parameters[0]

    @property
    def secondary(self) -> tuple:
        """Parameters fitted after the magnitude, on a grid between their bounds (the ground's damping beside
        its stiffness); the model's own coefficient until the data ask for another."""
        return self.parameters[1:]

    def search_bounds(self, base) -> tuple[float, float]:
        """(low, high) of the primary parameter's search, in search units (1/value for `inverse`)."""
        p = self.primary
        if p.relative:
            value = float(getattr(base, p.coefficient))
            return p.low * value, p.high * value
        return p.low, p.high

    def data_bounds(self, base, excited: dict) -> tuple[float, float]:
        """`search_bounds` narrowed to what a recording exciting `excited` (e.g. {"command": 9.5}, the largest
        commanded torque [N m]) can resolve."""
        low, high = self.search_bounds(base)
        p = self.primary
        if not p.resolved or p.resolved[0] not in excited:
            return low, high
        quantity, lo, hi = p.resolved
        scale = float(excited[quantity])
        if not scale > 0:
            return low, high
        values = sorted(self.search_value(f * scale) for f in (lo, hi))
        return max(low, values[0]), min(high, values[1])

    def coefficients(self, value: float, base=None) -> dict:
        """The coefficients this entry sets for a primary value in search units (`inverse`: 1/value)."""
        p = self.primary
        physical = self.physical(value)
        out = dict(self.fixed)
        if p.coefficient == "toe_mass":
            out["collision_factor"] = base.mass / (base.mass + physical)
        else:
            out[p.coefficient] = physical
        return out

    def physical(self, value: float) -> float:
        """The primary parameter in its physical unit, from the search value."""
        if self.primary.inverse:
            return math.inf if value <= 0 else 1.0 / value
        return float(value)

    def search_value(self, physical: float) -> float:
        if self.primary.inverse:
            return 0.0 if not math.isfinite(physical) or physical == 0 else 1.0 / physical
        return float(physical)

    def describe(self) -> dict:
        p = self.primary
        return {"name": self.name, "family": self.family, "site": self.site, "direction": self.direction,
                "kind": self.kind, "parameter": p.name, "unit": p.unit, "equation": self.equation,
                "words": self.words}


def _e(name, family, site, direction, param, equation, words, separate, **kw):
    return Effect(name, family, site, direction, (param,), equation, words, separate, **kw)


SPEEDS = "runs at several forward speeds and apex heights (speed-dependent laws separate from constant ones)"
TORQUES = "strides with tau_0 over a wide range, including tau_0 = 0 (actuator effects vanish without torque)"
HEIGHTS = "apex heights over a wide range (touchdown speeds differ, so do the impacts and compressions)"

LIBRARY: tuple[Effect, ...] = (
    # ---- flight resistance (2.8) and beyond
    _e("flight_damping_vertical", "flight resistance", "flight", "vertical",
       Parameter("d_v", "1/s", 0.0, 3.0, "flight_damping_z"),
       "z'' = -g - d_v z'  (2.8)", "the vertical flight damping differs from the model's", SPEEDS),
    _e("flight_damping_horizontal", "flight resistance", "flight", "horizontal",
       Parameter("d_h", "1/s", 0.0, 1.5, "flight_damping_y"),
       "y'' = -d_h y'  (2.8)", "the horizontal flight damping differs from the model's", SPEEDS),
    _e("quadratic_drag", "flight resistance", "flight", "both",
       Parameter("c", "1/m", 0.0, 0.6, "quadratic_drag"),
       "(y'', z'') += -c |v| (y', z')", "air drag quadratic in the speed", SPEEDS),
    _e("boom_friction_horizontal", "flight resistance", "flight", "horizontal",
       Parameter("a_y", "m/s^2", 0.0, 1.5, "flight_friction_y"),
       "y'' += -a_y sign(y')", "dry friction of the boom's vertical bearing (a constant drag on the forward motion)",
       SPEEDS),
    _e("boom_friction_vertical", "flight resistance", "flight", "vertical",
       Parameter("a_z", "m/s^2", 0.0, 1.5, "flight_friction_z"),
       "z'' += -a_z sign(z')", "dry friction of the boom's horizontal bearing (a constant drag on the vertical motion)",
       HEIGHTS),
    # ---- the boom
    _e("effective_gravity", "boom", "flight", "vertical",
       Parameter("g", "m/s^2", 0.75, 1.25, "gravity", relative=True),
       "z'' = -g ...  (4.5)-(4.7)", "the effective gravity of the boom differs from the model's", HEIGHTS),
    _e("horizontal_inertia", "boom", "stance_leg", "horizontal",
       Parameter("r", "", 0.0, 0.6, "horizontal_mass_ratio"),
       "m_b (1 + r) y'' = F_y in stance", "the boom's inertia makes the horizontal effective mass larger than the "
       "vertical", SPEEDS),
    # ---- touchdown
    _e("touchdown_loss_along", "touchdown", "touchdown", "along",
       Parameter("c_a", "", 0.0, 0.5, "touchdown_loss_along"),
       "v_along+ = (1 - c_a) v_along-", "a share of the velocity along the leg is lost at touchdown (the toe's and "
       "the leg's moving mass stops)", HEIGHTS),
    _e("touchdown_loss_across", "touchdown", "touchdown", "across",
       Parameter("c_c", "", 0.0, 0.3, "touchdown_loss_across"),
       "v_across+ = (1 - c_c) v_across-", "a share of the velocity across the leg is lost at touchdown (the leg's "
       "and rotor's inertia)", SPEEDS),
    # ---- the ground
    Effect("ground_compliance", "ground", "stance_leg", "along",
           (Parameter("k_g", "N/m", 0.0, 1e-4, "ground_stiffness", inverse=True),
            Parameter("d_g", "N s/m", 60.0, 1000.0, "ground_damping")),
           "k_g depth + d_g depth' = F_z  (massless toe)", "the ground gives under the toe like a spring "
           "and damper", HEIGHTS),
    _e("ground_height", "ground", "touchdown", "vertical",
       Parameter("h_g", "m", -0.02, 0.02, "ground_height"),
       "touchdown at z = h_g + rho_0 cos(theta)", "the ground is higher than the model has it (or the leg longer at "
       "touchdown)", HEIGHTS),
    _e("toe_slip", "ground", "stance_leg", "horizontal",
       Parameter("mu", "", 0.5, 10.0, "ground_friction", inverse=True),
       "the toe slides where |G_y| > mu G_z (G the leg's force on the ground; massless toe, the leg damper sets "
       "its speed)", "the toe slips on the ground: Coulomb friction between toe and ground (a slide where the "
       "leg's force leaves the friction cone, early in stance while the hip torque is large)",
       "a force plate (the ratio of horizontal to vertical force caps at mu), or a camera on the toe"),
    # ---- the leg in stance (2.9)
    _e("leg_stiffness", "leg", "stance_leg", "along",
       Parameter("k", "N/m", 0.8, 1.2, "stiffness", relative=True),
       "F = k (rho_0 - rho) - d rho'  (2.9)", "the leg spring's stiffness differs from the model's", HEIGHTS),
    _e("rest_length", "leg", "stance_leg", "along",
       Parameter("rho_0", "m", 0.93, 1.07, "rest_length", relative=True),
       "F = k (rho_0 - rho) ...  (2.9)", "the leg's rest length differs from the model's", HEIGHTS),
    _e("leg_damping", "leg", "stance_leg", "along",
       Parameter("d", "N s/m", 0.0, 3.0, "damping", relative=True),
       "F = ... - d rho'  (2.9)", "the leg's viscous damping differs from the model's", HEIGHTS),
    _e("spring_cubic", "leg", "stance_leg", "along",
       Parameter("k_3", "N/m^3", -3e6, 3e6, "spring_cubic"),
       "F += k_3 (rho_0 - rho)^3", "the leg spring is not linear (hardening when k_3 > 0)", HEIGHTS),
    _e("spring_preload", "leg", "stance_leg", "along",
       Parameter("F_p", "N", -30.0, 30.0, "spring_preload"),
       "F += F_p", "the leg spring is preloaded against the leg's stop (it is longer than the leg at rest)", HEIGHTS),
    _e("quadratic_leg_damping", "leg", "stance_leg", "along",
       Parameter("d_2", "N s^2/m^2", 0.0, 30.0, "quadratic_damping"),
       "F += -d_2 |rho'| rho'", "the leg's damping grows with the square of its speed", HEIGHTS),
    _e("leg_friction", "leg", "stance_leg", "along",
       Parameter("F_c", "N", 0.0, 8.0, "leg_friction"),
       "F += -F_c tanh(rho'/v_s)", "Coulomb friction in the leg slide", HEIGHTS),
    # ---- the hip actuator
    _e("torque_gain", "actuator", "actuator", "hip",
       Parameter("K", "", 0.3, 1.6, "torque_gain"),
       "tau = K tau_cmd", "the hip delivers a fixed fraction of the commanded torque (torque constant, gear "
       "efficiency)", TORQUES),
    _e("torque_offset", "actuator", "actuator", "hip",
       Parameter("tau_off", "N m", -1.5, 1.5, "torque_offset"),
       "tau = tau_cmd + tau_off in stance", "the hip adds a constant torque in stance (current offset)", TORQUES),
    _e("actuation_delay", "actuator", "actuator", "hip",
       Parameter("T_d", "s", 0.0, 0.015, "torque_delay"),
       "tau(t) = tau_cmd(t - T_d)", "the torque reaches the leg late", TORQUES),
    _e("actuator_lag", "actuator", "actuator", "hip",
       Parameter("T_l", "s", 0.0, 0.03, "torque_lag"),
       "T_l tau' + tau = tau_cmd", "the torque follows the command through a first-order lag (current loop, "
       "transmission)", TORQUES),
    _e("torque_saturation", "actuator", "actuator", "hip",
       Parameter("tau_max", "N m", 0.0, 0.6, "torque_limit", inverse=True, resolved=("command", 0.3, 1.0)),
       "|tau| <= tau_max", "the hip torque is clipped", TORQUES),
    _e("hip_viscous_friction", "actuator", "stance_hip", "hip",
       Parameter("b", "N m s/rad", 0.0, 0.3, "hip_viscous"),
       "tau += -b theta'", "viscous friction in the hip joint", SPEEDS),
    _e("hip_dry_friction", "actuator", "stance_hip", "hip",
       Parameter("f_h", "N m", 0.0, 1.5, "hip_friction"),
       "tau += -f_h tanh(theta'/w_s)", "dry friction in the hip joint", SPEEDS),
    # ---- the lift-off collision (2.12)
    _e("liftoff_collision", "liftoff", "liftoff", "both",
       Parameter("m_t", "kg", 0.0, 0.3, "toe_mass"),
       "v+ = m_b/(m_b + m_t) v-  (2.12)", "the toe mass of the lift-off collision differs from the model's", SPEEDS),
    # ---- the hip's inertia (added after the sweeps' seeds were fixed: bench/diagnosis_sim_sweep.py lists it last)
    _e("rotor_inertia", "actuator", "stance_hip", "hip, across at touchdown",
       Parameter("J", "kg m^2", 0.0, 0.015, "rotor_inertia"),
       "tau_e = (tau - J (A - 2 rho' theta')/rho) / (1 + J B/rho^2) in stance (2.9): tau - J theta''; at touchdown "
       "v_across+ = v_across- m rho_0^2/(m rho_0^2 + J)",
       "the hip motor's rotor seen through the gear (J_rotor N^2) turns with the leg: the still leg's rotor is spun "
       "up at touchdown at the body's expense, and in stance part of the hip torque turns it", SPEEDS),
)


def _sensor(channel, op, low, high, unit, plausible, words, base=0.0):
    name = f"{channel}_{op}"
    return Effect(name, "sensor", "sensor", channel,
                  (Parameter(name, unit, low, high, name, plausible=plausible),),
                  {"delay": f"{channel}_rec(t) = {channel}(t - T)", "scale": f"{channel}_rec = s {channel}",
                   "offset": f"{channel}_rec = {channel} + o"}[op], words,
                  "a second, independent measurement of the channel (e.g. a force plate or a camera)", kind="sensor")


SENSORS: tuple[Effect, ...] = (
    _sensor("z", "delay", 0.0, 0.01, "s", (0.001, 0.01), "the height channel lags"),
    _sensor("y", "delay", 0.0, 0.01, "s", (0.001, 0.01), "the forward position channel lags"),
    _sensor("theta", "delay", 0.0, 0.01, "s", (0.001, 0.01), "the leg angle channel lags"),
    _sensor("z", "scale", 0.9, 1.1, "", (0.005, 0.05), "the height channel is scaled (boom length or encoder "
            "resolution wrong)"),
    _sensor("y", "scale", 0.9, 1.1, "", (0.005, 0.05), "the forward position channel is scaled (boom length or "
            "encoder resolution wrong)"),
    _sensor("theta", "scale", 0.9, 1.1, "", (0.005, 0.05), "the leg angle channel is scaled (gear ratio or "
            "encoder resolution wrong)"),
    _sensor("z", "offset", -0.015, 0.015, "m", (0.001, 0.015), "the height channel is offset (boom height or "
            "ground level wrong)"),
    _sensor("theta", "offset", -0.06, 0.06, "rad", (0.005, 0.06), "the leg angle channel is offset (encoder zero "
            "wrong)"),
)
SENSOR_KEYS = tuple(e.primary.coefficient for e in SENSORS)
SENSOR_OFF = {key: (1.0 if key.endswith("scale") else 0.0) for key in SENSOR_KEYS}

EFFECTS: dict[str, Effect] = {e.name: e for e in LIBRARY + SENSORS}


def get(name: str) -> Effect:
    try:
        return EFFECTS[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; known: {', '.join(sorted(EFFECTS))}") from None


def apply(coefficients, settings: dict):
    """`coefficients` (laws.Coefficients) with named effects on: {name: physical magnitude}.

    Returns (coefficients, sensor faults {key: value}).
    """
    changes, sensors = {}, dict(SENSOR_OFF)
    for name, magnitude in settings.items():
        effect = get(name)
        values = effect.coefficients(effect.search_value(float(magnitude)), coefficients)
        if effect.kind == "sensor":
            sensors.update(values)
        else:
            changes.update(values)
    return coefficients.replace(**changes), sensors
