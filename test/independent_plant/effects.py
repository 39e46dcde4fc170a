"""The library of concealed effects (laws in README.md). Every effect acts in one place:

    flight            extra body acceleration while airborne
    touchdown         velocity reset or contact geometry at touchdown
    stance_along_leg  extra force along the leg (or the leg/ground structure under it)
    stance_hip        extra torque about the hip in stance (not commanded)
    actuator          commanded torque -> applied torque
    liftoff           the lift-off collision
    sensor_*          one measured channel only (the physics is untouched)
"""

from __future__ import annotations

import math

import numpy as np

from .plant import Effect, Model, StanceCtx, Structure

V_SMOOTH = 0.005      # [m/s] velocity scale of the smoothed sign() of dry friction laws
W_SMOOTH = 0.05       # [rad/s] angular-rate scale of the smoothed sign() at the hip


def _sgn(v: float, scale: float) -> float:
    return math.tanh(v / scale)


# ------------------------------------------------------------------------ flight resistance

class QuadraticDrag(Effect):
    id, family, site, direction = "air_drag_quadratic", "flight_resistance", "flight", "both"
    parameter, unit = "c_drag", "1/m"
    equation = "flight: (y'', z'') += -c_drag |v| (y', z'),  |v| = sqrt(y'^2 + z'^2)"
    words = ("Quadratic aerodynamic drag of the body and the swinging boom in flight, per unit "
             "mass, opposite to the velocity.")
    acts_in = ("flight",)

    def flight_accel(self, t, y, z, vy, vz, model):
        c = self.magnitude * math.hypot(vy, vz)
        return -c * vy, -c * vz


class BoomBearingCoulomb(Effect):
    id, family, site, direction = "boom_bearing_coulomb", "flight_resistance", "flight", "horizontal"
    parameter, unit = "a_c", "m/s^2"
    equation = "flight: y'' += -a_c sgn(y')   (sgn smoothed: tanh(y'/0.005))"
    words = ("Dry (Coulomb) friction of the planarizer's azimuth bearing: a constant horizontal "
             "deceleration while airborne.")
    acts_in = ("flight",)

    def flight_accel(self, t, y, z, vy, vz, model):
        return -self.magnitude * _sgn(vy, V_SMOOTH), 0.0


class ExtraVerticalDamping(Effect):
    id, family, site, direction = "flight_damping_vertical_extra", "flight_resistance", "flight", "vertical"
    parameter, unit = "delta_d_v", "1/s"
    equation = "flight: z'' += -delta_d_v z'   (i.e. d_v = 0.23 + delta_d_v)"
    words = "The vertical flight damping is larger than the identified d_v (per unit mass)."
    acts_in = ("flight",)

    def flight_accel(self, t, y, z, vy, vz, model):
        return 0.0, -self.magnitude * vz


class ExtraHorizontalDamping(Effect):
    id, family, site, direction = "flight_damping_horizontal_extra", "flight_resistance", "flight", "horizontal"
    parameter, unit = "delta_d_h", "1/s"
    equation = "flight: y'' += -delta_d_h y'   (i.e. d_h = 0.01 + delta_d_h)"
    words = "The horizontal flight damping is larger than the identified d_h (per unit mass)."
    acts_in = ("flight",)

    def flight_accel(self, t, y, z, vy, vz, model):
        return -self.magnitude * vy, 0.0


# ------------------------------------------------------------------------ boom

class GravityError(Effect):
    id, family, site, direction = "effective_gravity", "boom", "flight", "vertical"
    parameter, unit = "g_true", "m/s^2"
    equation = "z'' = -g_true - ... in flight and stance (model: g = 11.42)"
    words = ("The boom-corrected effective gravity differs from the identified 11.42 m/s^2; it "
             "acts in both phases but is seen best in the flight parabolas.")
    acts_in = ("flight", "stance")

    def configure(self, st: Structure, model: Model):
        st.g = self.magnitude


class BoomHorizontalInertia(Effect):
    id, family, site, direction = "boom_horizontal_inertia", "boom", "stance_along_leg", "horizontal"
    parameter, unit = "r", "1"
    equation = "stance: y'' = F_y / (m_b (1 + r)),  z'' = F_z / m_b - g"
    words = ("The boom's rotational inertia about the azimuth axis adds to the mass the leg "
             "has to accelerate horizontally: in stance the horizontal effective mass is "
             "m_b (1 + r) while the vertical one stays m_b.")
    acts_in = ("stance",)

    def configure(self, st, model):
        st.mass_ratio_h = self.magnitude


# ------------------------------------------------------------------------ touchdown

class TouchdownLossAlong(Effect):
    id, family, site, direction = "touchdown_loss_along", "touchdown", "touchdown", "along"
    parameter, unit = "e_along", "1"
    equation = "touchdown: v+ = v- - e_along (v-.u) u,  u = unit vector along the leg"
    words = ("At touchdown the impact of the toe and foot pad absorbs a share of the body's "
             "velocity component along the leg.")
    acts_in = ("touchdown",)

    def touchdown(self, vy, vz, theta, model):
        uy, uz = -math.sin(theta), math.cos(theta)
        p = vy * uy + vz * uz
        return vy - self.magnitude * p * uy, vz - self.magnitude * p * uz


class TouchdownLossAcross(Effect):
    id, family, site, direction = "touchdown_loss_across", "touchdown", "touchdown", "across"
    parameter, unit = "e_across", "1"
    equation = "touchdown: v+ = v- - e_across (v-.n) n,  n = unit vector across the leg"
    words = ("At touchdown the leg's own inertia swinging about the hip takes a share of the "
             "body's velocity component perpendicular to the leg.")
    acts_in = ("touchdown",)

    def touchdown(self, vy, vz, theta, model):
        ny, nz = -math.cos(theta), -math.sin(theta)
        p = vy * ny + vz * nz
        return vy - self.magnitude * p * ny, vz - self.magnitude * p * nz


# ------------------------------------------------------------------------ the leg in stance

class StiffnessError(Effect):
    id, family, site, direction = "stiffness_error", "stance_leg", "stance_along_leg", "along"
    parameter, unit = "delta_k", "N/m"
    equation = "stance: F_leg += delta_k (rho_0 - rho)   (k_true = 4696 + delta_k)"
    words = "The leg spring is stiffer than the identified k."
    acts_in = ("stance",)

    def stance_along(self, c: StanceCtx, model):
        return self.magnitude * (model.rho_0 - c.rho)


class RestLengthError(Effect):
    id, family, site, direction = "spring_rest_length_error", "stance_leg", "stance_along_leg", "along"
    parameter, unit = "delta_rho", "m"
    equation = ("stance: F_leg = k (rho_0 + delta_rho - rho) - d rho'; the leg stop (flight and "
                "touchdown length, lift-off at rho = rho_0) is unchanged")
    words = ("The spring's free length is longer than the leg's stop length, so the spring is "
             "preloaded against the stop: a force k delta_rho appears at touchdown and vanishes "
             "only at the stop.")
    acts_in = ("stance",)

    def configure(self, st, model):
        st.spring_rest = model.rho_0 + self.magnitude


class CubicSpring(Effect):
    id, family, site, direction = "spring_cubic", "stance_leg", "stance_along_leg", "along"
    parameter, unit = "k3", "N/m^3"
    equation = "stance: F_leg += k3 (rho_0 - rho)^3"
    words = "The leg spring hardens with compression (a cubic term on top of the linear law)."
    acts_in = ("stance",)

    def stance_along(self, c, model):
        return self.magnitude * (model.rho_0 - c.rho) ** 3


class QuadraticLegDamping(Effect):
    id, family, site, direction = "leg_damping_quadratic", "stance_leg", "stance_along_leg", "along"
    parameter, unit = "c2", "N s^2/m^2"
    equation = "stance: F_leg += -c2 |rho'| rho'"
    words = "Part of the leg's damping grows with the square of the compression speed."
    acts_in = ("stance",)

    def stance_along(self, c, model):
        return -self.magnitude * abs(c.rhodot) * c.rhodot


class LegCoulomb(Effect):
    id, family, site, direction = "leg_slide_coulomb", "stance_leg", "stance_along_leg", "along"
    parameter, unit = "f_c", "N"
    equation = "stance: F_leg += -f_c sgn(rho')   (sgn smoothed: tanh(rho'/0.005))"
    words = "Dry friction in the leg's linear slide opposes compression and extension alike."
    acts_in = ("stance",)

    def stance_along(self, c, model):
        return -self.magnitude * _sgn(c.rhodot, V_SMOOTH)


class CompliantGround(Effect):
    id, family, site, direction = "compliant_ground", "stance_leg", "stance_along_leg", "vertical"
    parameter, unit = "k_g", "N/m"
    equation = ("stance: the toe (massless) rests on a ground spring-damper: "
                "-k_g (z_toe - h) - d_g z_toe' = vertical leg force; the leg acts between body and toe")
    words = ("The running surface gives under the toe like a spring with a damper in series with "
             "the leg.")
    acts_in = ("stance",)

    def __init__(self, magnitude, d_g):
        super().__init__(magnitude)
        self.d_g = float(d_g)
        self.equation = self.equation + f"; d_g = {self.d_g:g} N s/m"

    def configure(self, st, model):
        st.ground_k, st.ground_d = self.magnitude, self.d_g

    def describe(self):
        out = super().describe()
        out["parameters"] = {"k_g": self.magnitude, "d_g": self.d_g}
        return out


# ------------------------------------------------------------------------ the hip actuator

class ActuatorGain(Effect):
    id, family, site, direction = "actuator_gain", "actuator", "actuator", None
    parameter, unit = "gain", "1"
    equation = "tau_applied(s) = gain * tau_cmd(s)"
    words = "The hip motor delivers only a fixed fraction of the commanded torque."
    acts_in = ("stance",)

    def actuator(self, law):
        gain = self.magnitude
        return lambda s: gain * law(s)


class ActuatorOffset(Effect):
    id, family, site, direction = "actuator_offset", "actuator", "actuator", None
    parameter, unit = "tau_offset", "N m"
    equation = "stance: tau_applied(s) = tau_cmd(s) + tau_offset  (whole stance, torque mode)"
    words = ("A current-sensing offset of the motor driver adds a constant torque for the whole "
             "time the motor is in torque mode (stance).")
    acts_in = ("stance",)

    def actuator(self, law):
        off = self.magnitude
        return lambda s: law(s) + off


class ActuatorDelay(Effect):
    id, family, site, direction = "actuator_delay", "actuator", "actuator", None
    parameter, unit = "delay", "s"
    equation = "tau_applied(s) = tau_cmd(s - delay)  (zero for s < delay)"
    words = "The torque reaches the leg a fixed time after it is commanded (bus and driver latency)."
    acts_in = ("stance",)

    def actuator(self, law):
        dl = self.magnitude
        return lambda s: law(s - dl)

    def actuator_kinks(self, t_f):
        return [self.magnitude, t_f + self.magnitude]


class ActuatorLag(Effect):
    id, family, site, direction = "actuator_lag", "actuator", "actuator", None
    parameter, unit = "T_lag", "s"
    equation = "T_lag tau_applied' = tau_cmd - tau_applied,  tau_applied = 0 at touchdown"
    words = "The applied torque follows the command through a first-order lag (current loop, winding inductance)."
    acts_in = ("stance",)

    def configure(self, st, model):
        st.lag_T = self.magnitude


class ActuatorSaturation(Effect):
    id, family, site, direction = "actuator_saturation", "actuator", "actuator", None
    parameter, unit = "tau_max", "N m"
    equation = "tau_applied = clip(tau_cmd, -tau_max, tau_max)"
    words = "The motor driver's current limit caps the hip torque."
    acts_in = ("stance",)

    def actuator(self, law):
        m = self.magnitude
        return lambda s: min(max(law(s), -m), m)


class HipViscous(Effect):
    id, family, site, direction = "hip_friction_viscous", "actuator", "stance_hip", None
    parameter, unit = "b_hip", "N m s/rad"
    equation = "stance: tau += -b_hip theta'"
    words = "Viscous friction in the hip gearbox opposes the leg's rotation relative to the body."
    acts_in = ("stance",)

    def stance_hip(self, c, model):
        return -self.magnitude * c.thetadot


class HipCoulomb(Effect):
    id, family, site, direction = "hip_friction_coulomb", "actuator", "stance_hip", None
    parameter, unit = "tau_c", "N m"
    equation = "stance: tau += -tau_c sgn(theta')   (sgn smoothed: tanh(theta'/0.05))"
    words = "Dry friction in the hip gearbox opposes the leg's rotation with a constant torque."
    acts_in = ("stance",)

    def stance_hip(self, c, model):
        return -self.magnitude * _sgn(c.thetadot, W_SMOOTH)


# ------------------------------------------------------------------------ lift-off

class ToeMassError(Effect):
    id, family, site, direction = "liftoff_toe_mass", "liftoff", "liftoff", "both"
    parameter, unit = "m_t_true", "kg"
    equation = "lift-off: v+ = m_b / (m_b + m_t_true) v-   (model: m_t = 0.03)"
    words = "The lift-off collision takes more velocity than the identified toe mass implies."
    acts_in = ("liftoff",)

    def configure(self, st, model):
        st.m_t = self.magnitude


# ------------------------------------------------------------------------ sensors

class _Sensor(Effect):
    family = "sensor"
    direction = None
    acts_in = ("sensor",)

    def __init__(self, magnitude, channel: str):
        super().__init__(magnitude)
        assert channel in ("y", "z", "theta")
        self.channel = channel
        self.site = f"sensor_{channel}"
        self.id = f"{self.kind}_{channel}"


class SensorDelay(_Sensor):
    kind, parameter, unit = "sensor_delay", "delay", "s"

    def __init__(self, magnitude, channel):
        super().__init__(magnitude, channel)
        self.equation = f"{channel}_meas(t) = {channel}(t - delay)"
        self.words = f"The {channel} channel is read out with a fixed latency relative to the others."

    def sensor(self, channel, t, values, traj):
        if channel != self.channel:
            return values
        tq = np.maximum(t - self.magnitude, traj.run_start(t))
        return traj.eval(tq)[("y", "z", "theta").index(channel)]


class SensorScale(_Sensor):
    kind, parameter, unit = "sensor_scale", "scale", "1"

    def __init__(self, magnitude, channel):
        super().__init__(magnitude, channel)
        self.equation = f"{channel}_meas = scale * {channel}"
        self.words = (f"The {channel} channel's calibration factor is off (e.g. the boom radius "
                      "used to convert the encoder angle).")

    def sensor(self, channel, t, values, traj):
        return values * self.magnitude if channel == self.channel else values


class SensorOffset(_Sensor):
    kind, parameter = "sensor_offset", "offset"

    def __init__(self, magnitude, channel):
        super().__init__(magnitude, channel)
        self.unit = "rad" if channel == "theta" else "m"
        self.equation = f"{channel}_meas = {channel} + offset"
        self.words = f"The {channel} encoder's zero (homing) is off by a constant."

    def sensor(self, channel, t, values, traj):
        return values + self.magnitude if channel == self.channel else values


# ------------------------------------------------------------------------ other effects

class FlightLift(Effect):
    id, family, site, direction = "flight_counterweight_lift", "other", "flight", "vertical"
    parameter, unit = "a_lift", "m/s^2"
    equation = "flight only: z'' += a_lift   (the cable is slack in stance)"
    words = ("A boom counterweight on a cable lifts the robot with a constant force while it is "
             "airborne; the cable goes slack when the leg is loaded.")
    acts_in = ("flight",)

    def flight_accel(self, t, y, z, vy, vz, model):
        return 0.0, self.magnitude


class Tether(Effect):
    id, family, site, direction = "flight_tether_high", "other", "flight", "vertical"
    parameter, unit = "kappa", "1/s^2"

    def __init__(self, magnitude, z_c):
        super().__init__(magnitude)
        self.z_c = float(z_c)
        self.equation = f"flight: z'' += -kappa (z - z_c) for z > z_c = {self.z_c:g} m (else 0)"
        self.words = ("A safety tether becomes taut above a height and pulls the body down "
                      "elastically: only high apexes are affected.")

    acts_in = ("flight",)

    def flight_accel(self, t, y, z, vy, vz, model):
        return 0.0, (-self.magnitude * (z - self.z_c) if z > self.z_c else 0.0)

    def describe(self):
        out = super().describe()
        out["parameters"] = {"kappa": self.magnitude, "z_c": self.z_c}
        return out


class HipTorsionSpring(Effect):
    id, family, site, direction = "hip_torsion_spring", "other", "stance_hip", None
    parameter, unit = "kappa_hip", "N m/rad"
    equation = "stance: tau += -kappa_hip theta"
    words = ("A torsional spring at the hip (the cable harness) pulls the leg towards the "
             "vertical during stance, when the motor is in torque mode.")
    acts_in = ("stance",)

    def stance_hip(self, c, model):
        return -self.magnitude * c.theta


class GroundHigher(Effect):
    id, family, site, direction = "ground_higher", "other", "touchdown", "vertical"
    parameter, unit = "h_ground", "m"
    equation = "touchdown when z - rho_0 cos(theta) = h_ground; stance about a toe at z = h_ground"
    words = ("The running surface is higher than the level the heights are measured from (a mat "
             "on the floor).")
    acts_in = ("touchdown", "stance")

    def configure(self, st, model):
        st.ground_h = self.magnitude


class ToeSlip(Effect):
    id, family, site, direction = "toe_slip", "other", "stance_along_leg", "horizontal"
    parameter, unit = "mu_k", "1"

    def __init__(self, magnitude, mu_s):
        super().__init__(magnitude)
        self.mu_s = float(mu_s)
        self.equation = ("stance: the toe sticks while |G_y| <= mu_s G_z, else slides with "
                         f"G_y = -sgn(y_toe') mu_k G_z (massless toe); mu_s = {self.mu_s:g}")
        self.words = ("The toe slips on the ground when the ground force leaves the friction cone "
                      "(steep legs at touchdown and lift-off, large hip torque).")

    acts_in = ("stance",)

    def configure(self, st, model):
        st.slip_mu_s, st.slip_mu_k = self.mu_s, self.magnitude

    def describe(self):
        out = super().describe()
        out["parameters"] = {"mu_k": self.magnitude, "mu_s": self.mu_s}
        return out


class BumpStop(Effect):
    id, family, site, direction = "leg_bump_stop", "other", "stance_along_leg", "along"
    parameter, unit = "k_stop", "N/m"

    def __init__(self, magnitude, engage):
        super().__init__(magnitude)
        self.engage = float(engage)
        self.equation = (f"stance: F_leg += k_stop (rho_0 - {self.engage:g} - rho) when "
                         f"rho < rho_0 - {self.engage:g} m (else 0)")
        self.words = ("A rubber bump stop in the leg engages after a given compression and adds "
                      "its stiffness: a leg-length dependent force felt only in deep compressions.")

    acts_in = ("stance",)

    def stance_along(self, c, model):
        x = model.rho_0 - self.engage - c.rho
        return self.magnitude * x if x > 0 else 0.0

    def describe(self):
        out = super().describe()
        out["parameters"] = {"k_stop": self.magnitude, "engage_compression": self.engage}
        return out


class BoomBending(Effect):
    id, family, site, direction = "boom_bending_after_liftoff", "other", "sensor_z", "vertical"
    parameter, unit = "amplitude", "m"

    def __init__(self, magnitude, freq, zeta):
        super().__init__(magnitude)
        self.freq, self.zeta = float(freq), float(zeta)
        self.equation = ("z_meas = z - A exp(-zeta w s) sin(w_d s), s = time since lift-off, "
                         f"w = 2 pi {self.freq:g} Hz, zeta = {self.zeta:g}, w_d = w sqrt(1-zeta^2)")
        self.words = ("The lift-off collision excites the boom's bending mode: the elevation "
                      "encoder at the boom root sees a decaying oscillation the body does not have.")

    acts_in = ("sensor",)

    def sensor(self, channel, t, values, traj):
        if channel != "z":
            return values
        lo = np.asarray(traj.liftoffs)
        if lo.size == 0:
            return values
        w = 2 * math.pi * self.freq
        wd = w * math.sqrt(1 - self.zeta ** 2)
        idx = np.searchsorted(lo, t, side="right") - 1
        out = values.copy()
        ok = idx >= 0
        s = t[ok] - lo[idx[ok]]
        out[ok] -= self.magnitude * np.exp(-self.zeta * w * s) * np.sin(wd * s)
        return out

    def describe(self):
        out = super().describe()
        out["parameters"] = {"amplitude": self.magnitude, "freq_hz": self.freq, "zeta": self.zeta}
        return out
