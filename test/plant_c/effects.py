"""Plant C's mechanisms: physics a real boom-mounted hopper has and the extended TD-SLIP model
leaves out.  Each is a Mechanism (plant.py) with its id, words, equation, parameters, the
phase(s) where it acts and one magnitude.  Symbols: x = rho0 - rho the leg's compression,
s the time since touchdown, p = (y, z) the body, theta the leg angle, tau the hip torque on the
leg (positive increases theta), m the body mass (2.20 kg).

None of them is one of the tool's single-parameter laws (air drag, boom friction, gravity,
boom inertia, touchdown losses, raised floor, compliant ground, toe slip, leg stiffness / rest
length / preload / cubic spring / quadratic damping / dry friction, hip torque gain / offset /
delay / lag / saturation / friction, toe mass, sensor delay / scale / offset).
"""

from __future__ import annotations

import math

import numpy as np

from plant import Mechanism

TRACK = 2 * math.pi * (1.65 + 0.09)   # [m] one lap of y (forward position at 1.74 m radius)


class LegSwingReaction(Mechanism):
    id = "leg_swing_reaction"
    family = "leg mass and inertia swinging in flight"
    site = "flight"
    unit = "m"
    words = ("The leg is not massless: its mass m_l, centred r_c below the hip, swings from "
             "the lift-off angle to the next touchdown angle during flight. The centre of "
             "mass of body + leg follows the ballistic flight (2.8), so the body recoils "
             "against the leg's swing (by ~mu r_c (sin th_td - sin th_lo) forward/back).")
    equation = ("flight: p'' = [-d_h y', -g - d_v z'] - mu r_c d^2/dt^2 (sin theta, -cos theta),"
                " mu = m_l/(m_b + m_l)")

    @classmethod
    def defaults(cls):
        return {"m_l": 0.30, "r_c": 0.09}

    @property
    def magnitude(self):  # [m] the body's recoil per unit change of sin(theta)
        return self.m_l / (2.20 + self.m_l) * self.r_c

    def force(self, c):
        if c.phase != "flight":
            return 0.0, 0.0
        mu = self.m_l / (self.plant.p.m_b + self.m_l)
        s, co = math.sin(c.th), math.cos(c.th)
        ay = -mu * self.r_c * (c.thdd * co - c.thd * c.thd * s)
        az = -mu * self.r_c * (c.thdd * s + c.thd * c.thd * co)
        return self.plant.m_y * ay, self.plant.m_z * az


class AirChamber(Mechanism):
    id = "air_chamber"
    family = "trapped air in the telescoping leg, adiabatic with a leaking orifice"
    site = "stance"
    unit = "N/m"
    n_states = 1
    words = ("The leg's telescope traps air in a chamber (piston area A, volume V0 at rest "
             "length) that is compressed adiabatically with the leg and leaks to the "
             "atmosphere through an orifice with time constant tau_l. It adds a stiffness "
             "gamma p_a A^2/V0 at fast compression that relaxes, a rate-dependent (Maxwell-"
             "like) spring with an energy loss, and pulls the leg in (p < p_a) late in stance.")
    equation = ("F_air = (p - p_a) A along the leg; dp/dt = gamma p A x'/(V0 - A x) - "
                "(p - p_a)/tau_l, x = rho0 - rho (in flight x = 0 and p relaxes to p_a)")

    @classmethod
    def defaults(cls):
        return {"A": 4.2e-4, "V0": 4.2e-5, "p_a": 101325.0, "gamma": 1.4, "tau_l": 0.03}

    @property
    def magnitude(self):  # [N/m] small-signal adiabatic stiffness
        return self.gamma * self.p_a * self.A**2 / self.V0

    def init_states(self, *a):
        return [0.0]  # (p - p_a)/p_a

    def deriv(self, c):
        s = c.X[self.slot]
        V = self.V0 - self.A * c.x
        return [self.gamma * (1.0 + s) * self.A * c.xd / V - s / self.tau_l]

    def leg_force(self, c):
        return c.X[self.slot] * self.p_a * self.A


class SpringHysteresis(Mechanism):
    id = "spring_hysteresis"
    family = "rate-independent hysteresis of the leg spring (Bouc-Wen element)"
    site = "stance"
    unit = "N"
    n_states = 1
    words = ("The leg spring's seat/bushing adds a rate-independent hysteretic force (a "
             "Bouc-Wen element of stiffness k_h and yield displacement x_y, e.g. an "
             "elastomer seat or a composite spring): it grows elastically after each "
             "reversal of the compression and saturates at +-k_h x_y, so the same loop is "
             "lost each stance whatever the speed, with a smooth (not Coulomb) turn-around "
             "at the bottom. The element starts unstrained at each touchdown.")
    equation = ("F_leg = k x - d rho' + k_h w; w' = x' - (|x'| w + x' |w|)/(2 x_y), w = 0 at "
                "touchdown (x = rho0 - rho)")

    @classmethod
    def defaults(cls):
        return {"k_h": 1500.0, "x_y": 0.002}

    @property
    def magnitude(self):  # [N] the hysteretic force's bound
        return self.k_h * self.x_y

    def deriv(self, c):
        if c.phase != "stance":
            return [0.0]
        w = c.X[self.slot]
        xd = c.xd
        return [xd - (abs(xd) * w + xd * abs(w)) / (2 * self.x_y)]

    def leg_force(self, c):
        return self.k_h * c.X[self.slot]

    def on_touchdown(self, plant, t, X):
        X[self.slot] = 0.0
        return X


class MotorBackEmf(Mechanism):
    id = "motor_back_emf"
    family = "hip motor's speed-dependent torque limit (back-EMF against the supply voltage)"
    site = "stance"
    unit = "V"
    torque_order = 10
    words = ("The hip motor's current is limited by the drive's output voltage: the winding "
             "resistance R (with cables) and the back-EMF k_t G theta' leave (V - k_t G "
             "theta')/R at most, so while the leg sweeps backward under a forward-driving "
             "torque the torque the leg gets falls with the sweep speed; the command is clipped"
             " (more at high speed and early in stance where the ramp is high).")
    equation = ("i = clip(tau_cmd/(G k_t), (-V - k_t G theta')/R, (V - k_t G theta')/R); "
                "tau = G k_t i (stance)")

    @classmethod
    def defaults(cls):
        return {"V": 9.0, "R": 0.6, "k_t": 0.02411, "G": 26.0}

    @property
    def magnitude(self):  # [V] the drive's available voltage
        return self.V

    def hip_torque(self, tau, c):
        kg = self.k_t * self.G
        e = kg * c.thd
        i = tau / kg
        i = min(max(i, (-self.V - e) / self.R), (self.V - e) / self.R)
        return kg * i


class BoomBending(Mechanism):
    id = "boom_bending"
    family = "the boom's vertical bending mode between the encoder and the body"
    site = ["flight", "stance", "sensor"]
    unit = "m/N"
    n_states = 2
    boom_mass = 0.5
    words = ("The boom is not rigid: a part m_1 of the moving mass (the boom's effective tip "
             "mass) follows the elevation encoder while the body (m_b - m_1, where the leg "
             "acts) is joined to it by the boom's bending stiffness k_b with damping ratio "
             "zeta. The leg force bends the boom in stance, the mode rings after touchdown and "
             "lift-off, and z (from the encoder) is the boom's, not the hip's, height.")
    equation = ("(m_b - m_1) z2'' = F_leg,z - (m_b - m_1) g - k_b (z2 - z1) - c_b (z2' - z1');"
                " m_1 z1'' = -m_1 g + k_b (z2 - z1) + c_b (z2' - z1') (+ flight damping on "
                "both); forward both move together (m_b y'' = F_leg,y); collision (2.12) with "
                "m_b - m_1 vertically; z_measured = z1; c_b = 2 zeta sqrt(k_b m_1 m_2/m_b)")

    @classmethod
    def defaults(cls):
        return {"m_1": 0.5, "k_b": 8000.0, "zeta": 0.03}

    def __init__(self, **kw):
        super().__init__(**kw)
        self.boom_mass = self.m_1

    @property
    def magnitude(self):  # [m/N] the boom's compliance at the body
        return 1.0 / self.k_b

    @property
    def c_b(self):
        m2 = 2.20 - self.m_1
        return 2 * self.zeta * math.sqrt(self.k_b * self.m_1 * m2 / 2.20)

    def init_states(self, y, z, vy, vz):
        return [z, vz]

    def _spring(self, c):
        z1, v1 = c.X[self.slot], c.X[self.slot + 1]
        return self.k_b * (c.z - z1) + self.c_b * (c.vz - v1)

    def force(self, c):
        return 0.0, -self._spring(c)

    def deriv(self, c):
        p = self.plant.p
        v1 = c.X[self.slot + 1]
        a = -p.g + self._spring(c) / self.m_1
        if c.phase == "flight":
            a -= p.d_v * v1
        return [v1, a]

    def sense(self, ch):
        ch["meas"]["z"] = ch["X"][self.slot].copy()


class TiltedPivot(Mechanism):
    id = "tilted_pivot"
    family = "the boom's pivot axis tilted: the floor undulates once per lap"
    site = ["flight", "touchdown", "stance"]
    unit = "m"
    words = ("The boom's vertical axis is tilted, so in the boom's own coordinates (the ones "
             "the encoders measure) the floor rises and falls once per lap by +-a, and "
             "gravity has a component along the track (downhill where the measured floor "
             "rises).")
    equation = ("h(y) = a sin(2 pi y/L + phi) (touchdown: z - rho0 cos theta = h(y_toe)); "
                "F_y = m g h'(y) in flight and stance; L = 2 pi 1.74 m")

    @classmethod
    def defaults(cls):
        return {"a": 0.02, "L": TRACK, "phi": 0.7}

    @property
    def magnitude(self):
        return self.a

    def floor(self, y):
        return self.a * math.sin(2 * math.pi * y / self.L + self.phi)

    def force(self, c):
        slope = self.a * 2 * math.pi / self.L * math.cos(2 * math.pi * c.y / self.L + self.phi)
        return self.plant.m_y * self.plant.p.g * slope, 0.0


class FloorBoard(Mechanism):
    id = "floor_board"
    family = "a board on part of the track: a stepped floor"
    site = "touchdown"
    unit = "m"
    words = ("A board of thickness H covers a stretch of the circular track (from y0 over a "
             "length l, every lap L): strides that touch down on it meet the floor H higher; "
             "a toe that meets the board's edge from below is caught there.")
    equation = ("h(y) = H if (y mod L) in [y0, y0 + l) else 0; touchdown when z - rho0 cos "
                "theta = h(y_toe)")

    @classmethod
    def defaults(cls):
        return {"H": 0.02, "y0": 2.0, "l": 4.0, "L": TRACK}

    @property
    def magnitude(self):
        return self.H

    def floor(self, y):
        u = y % self.L
        return self.H if self.y0 <= u < self.y0 + self.l else 0.0


class AzimuthEccentricity(Mechanism):
    id = "azimuth_eccentricity"
    family = "periodic error of the forward-position encoder (pulley eccentricity)"
    site = "sensor"
    unit = "m"
    words = ("The azimuth encoder turns 6 times per lap through a belt; the eccentricity of "
             "its pulley gives a periodic error in y with the pulley's period (L/6 = 1.82 m "
             "of track): y and the forward speed read from it are wrong by up to e and "
             "2 pi e/P y'.")
    equation = "y_measured = y + e sin(2 pi y/P + phi), P = L/6"

    @classmethod
    def defaults(cls):
        return {"e": 0.003, "P": TRACK / 6, "phi": 1.3}

    @property
    def magnitude(self):
        return self.e

    def sense(self, ch):
        y = ch["y"]
        ch["meas"]["y"] = ch["meas"]["y"] + self.e * np.sin(2 * np.pi * y / self.P + self.phi)


class ElevationCouplingSlip(Mechanism):
    id = "elevation_coupling_slip"
    family = "the elevation encoder's coupling slips at the touchdown shocks"
    site = "sensor"
    unit = "m"
    words = ("The elevation encoder's shaft coupling slips at each touchdown shock: the "
             "encoder disc overruns downward by a random number of counts (Poisson, mean "
             "lambda), so the measured height drifts down through a recording (it is not "
             "re-homed between throws).")
    equation = ("z_measured(t) = z(t) - dz * sum over touchdowns t_i <= t of n_i, n_i ~ "
                "Poisson(lambda), dz = 2 pi 1.65 m / 49152")

    @classmethod
    def defaults(cls):
        return {"lam": 2.0, "dz": 2 * math.pi * 1.65 / 49152}

    def __init__(self, **kw):
        super().__init__(**kw)
        self.slips = []  # (t_touchdown, counts)

    @property
    def magnitude(self):  # [m] mean slip per touchdown
        return self.lam * self.dz

    def on_touchdown(self, plant, t, X):
        self.slips.append((t, int(plant.rng.poisson(self.lam))))
        return X

    def sense(self, ch):
        if not self.slips:
            return
        ts = np.array([s[0] for s in self.slips])
        cum = np.cumsum([s[1] for s in self.slips]) * self.dz
        i = np.searchsorted(ts, ch["t"], side="right")
        off = np.where(i > 0, cum[np.maximum(i - 1, 0)], 0.0)
        ch["meas"]["z"] = ch["meas"]["z"] - off


class GearWindup(Mechanism):
    id = "gear_windup"
    family = "torsional compliance between the motor encoder and the leg (angle read before it)"
    site = "sensor"
    unit = "rad/(N m)"
    words = ("The leg angle is read by the motor's encoder before the 1:26 gear, the "
             "coupling and the leg tube, which wind up by tau/K_w under the torque they "
             "carry: the hip torque in stance, the leg's inertial torque J_l theta'' in "
             "flight. The angle read leads the leg by tau/K_w.")
    equation = ("theta_measured = theta + tau_transmitted/K_w; tau_transmitted = tau (stance),"
                " J_l theta'' (flight)")

    @classmethod
    def defaults(cls):
        return {"K_w": 1500.0, "J_l": 2.0e-3}

    @property
    def magnitude(self):
        return 1.0 / self.K_w

    def sense(self, ch):
        tr = np.where(ch["stance"], ch["tau_app"], self.J_l * ch["thdd"])
        ch["meas"]["theta"] = ch["meas"]["theta"] + tr / self.K_w


class RoundFoot(Mechanism):
    id = "round_foot"
    family = "a round foot rolling on the floor"
    site = ["touchdown", "stance"]
    unit = "m"
    words = ("The toe is a ball of radius r_f (the leg's rest length reaches its bottom "
             "along the leg's axis) that rolls without slipping: the contact point moves "
             "forward r_f per radian the leg turns, touchdown comes r_f (1 - cos theta) "
             "earlier, and the leg's axis no longer passes through the contact point.")
    equation = ("stance: p = c + (rho - r_f) (-sin theta, cos theta), c = (c_0 - r_f (theta - "
                "theta_td), h + r_f); touchdown when z - (rho0 - r_f) cos theta - r_f = h")

    @classmethod
    def defaults(cls):
        return {"r_f": 0.025}

    def __init__(self, **kw):
        super().__init__(**kw)
        self.foot_radius = self.r_f

    @property
    def magnitude(self):
        return self.r_f


class BoomCentripetal(Mechanism):
    id = "boom_centripetal"
    family = "the boom's sphere: forward speed pulls the raised body down (centripetal)"
    site = ["flight", "stance"]
    unit = "m/s^2"
    words = ("The body moves on a sphere about the boom's pivot (radius R, pivot level z_p). "
             "When the boom is raised by beta ~ (z - z_p)/R the centripetal acceleration "
             "of the forward speed has a component -beta y'^2/R along the elevation, and the "
             "angular momentum about the vertical axis gives a Coriolis term along the track "
             "(the gravity part of the curvature is counted in the corrected g).")
    equation = ("z'' += -(z - z_p) y'^2/R^2; y'' += 2 (z - z_p) z' y'/R^2 (flight and stance)")

    @classmethod
    def defaults(cls):
        return {"R": 1.65, "z_p": 0.115}

    @property
    def magnitude(self):  # [m/s^2] at 2 m/s and z = 0.35 m
        return (0.35 - self.z_p) * 4.0 / self.R**2

    def force(self, c):
        e = (c.z - self.z_p) / self.R**2
        return self.plant.m_y * 2 * e * c.vz * c.vy, -self.plant.m_z * e * c.vy * c.vy


class ServoHandoff(Mechanism):
    id = "servo_handoff"
    family = "the leg's position servo released late after touchdown"
    site = "stance"
    unit = "N m/rad"
    torque_order = 0
    words = ("The flight position servo that holds theta_td stays on for t_h after touchdown "
             "(the pre-touchdown detection is late), so in early stance the leg is pulled "
             "back toward theta_td with stiffness K_p while it sweeps: a torque that opposes "
             "the sweep and grows with it, on top of the ramp.")
    equation = "tau = tau_cmd - K_p (theta - theta_td) for 0 <= s < t_h (stance)"

    @classmethod
    def defaults(cls):
        return {"K_p": 15.0, "t_h": 0.025}

    @property
    def magnitude(self):
        return self.K_p

    def hip_torque(self, tau, c):
        if c.s < self.t_h:
            return tau - self.K_p * (c.th - c.th_td)
        return tau

    def breakpoints(self):
        return [self.t_h]


REGISTRY = {cls.id: cls for cls in (
    LegSwingReaction, AirChamber, SpringHysteresis, MotorBackEmf, BoomBending, TiltedPivot,
    FloorBoard, AzimuthEccentricity, ElevationCouplingSlip, GearWindup, RoundFoot,
    BoomCentripetal, ServoHandoff)}


def make(mechanism_id: str, **parameters) -> Mechanism:
    return REGISTRY[mechanism_id](**parameters)
