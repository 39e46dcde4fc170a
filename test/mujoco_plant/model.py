"""The boom-mounted one-legged hopper of Orhon (2018) as a MuJoCo model (MJCF built here).

World frame: z up, the floor (the running surface) is the plane z = 0.  The boom's pivot is on
the vertical axis through the origin, 0.115 m above the running surface (appendix A: the body is
0.135 m above the floor at zero elevation; section 4.1: the running surface is 0.02 m above the
floor).

Boom ("hinge", the default): MuJoCo's own joints, as the planarizer is built (section 3.3):
  azimuth   hinge about the vertical axis through the pivot (the body goes round the circle)
  elevation hinge about the horizontal tangent axis at the pivot (the boom tilts up/down);
            the boom is a massless link of 1.65 m (its mass is in the thesis's corrected g,
            section 4.3.1.1, which is why gravity is 11.42 m/s^2 here)
  level     hinge at the boom's tip, held at -elevation by a stiff joint equality: the 4-bar
            that keeps the robot's body upright
  the body (hip) 0.09 m beyond the tip (appendix A's leg offset): the hip is at radius
  1.65 cos(elevation) + 0.09 from the vertical axis, at height 0.115 + 1.65 sin(elevation).
  Channels: y = 1.74 azimuth (arc length at the encoder conversion's radius, as appendix A's
  code), z = 0.115 + 1.65 sin(elevation).
Boom ("planar"): two slide joints (y forward, z up): the boom of infinite radius.

Leg: hip hinge (axis radial, positive swings the toe forward, +y) carrying the upper leg (mass
m_leg, centre r_c below the hip, own inertia); inside it the prismatic leg joint (positive
extends) with MuJoCo joint stiffness k (springref at rest length rho0) and damping d, limited at
rho0 (the leg's stopper: the lift-off collision happens against this limit); the toe body
(sphere of radius r_toe, mass m_toe) on it.  rho = hip to the sphere's lowest point when the
leg is vertical = rho0 + q_leg.  The hip motor is a torque actuator (ctrl = hip torque, N m,
range +-12.5 N m: 20 A x 0.02411 N m/A x 26), with the rotor's inertia as joint armature
(8.5e-6 kg m^2 x 26^2 = 5.75e-3 kg m^2) and the gear's viscous friction as joint damping
(1e-4 x 26^2 = 0.0676 N m s/rad) (config/hardware.yaml).

Flight damping (2.8) as joint damping on the boom's joints: d_h M R_y^2 on the azimuth,
d_v M R_e^2 on the elevation (M the whole robot's mass, R_y = 1.74 m, R_e = 1.65 m), so the
flight is (2.8) per unit mass; MuJoCo also applies it in stance (the thesis neglects it there).

Contact: the toe sphere against the floor plane, MuJoCo's soft contact (condim 3, pyramidal
cone, friction 1.0), solref/solimp per variant (MuJoCo's default solref (0.02, 1) lets the
30 g toe, pressed by the leg spring's 100-300 N, sink 3 cm into the floor: mj_default uses a
2 ms time constant, 1 mm at peak force).  Integrator RK4 (MuJoCo's own), timestep 0.25 ms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np

from nominal import Nominal, load_nominal

R_ELEV = 1.65          # [m] boom length, pivot to tip (appendix A)
LEG_OFFSET = 0.09      # [m] hip beyond the tip (appendix A)
R_AZ = R_ELEV + LEG_OFFSET
Z_PIVOT = 0.135 - 0.02  # [m] pivot height above the running surface
GEAR = 26.0
ROTOR_INERTIA = 8.5e-6
GEAR_VISCOUS = 1.0e-4
TORQUE_LIMIT = 20.0 * 0.02411 * GEAR

# encoders (config/hardware.yaml): counts per turn of the encoder's axis
AZ_COUNTS = 2048 * 4 * 6          # per boom turn
EL_COUNTS = 2048 * 4 * 6
MOTOR_COUNTS = 500 * 4 * 26       # per leg turn


@dataclass(frozen=True)
class Variant:
    name: str = "mj_default"
    boom: str = "hinge"                 # "hinge" | "planar"
    m_body: float = 2.00                # [kg] the body that does not rotate with the leg
    m_leg: float = 0.20                 # [kg] upper leg (rotates with the hip, above the spring)
    r_leg: float = 0.05                 # [m] its centre below the hip
    i_leg: float = 2.4e-4               # [kg m^2] its own inertia about its centre
    m_toe: float = 0.03                 # [kg] toe (below the spring)
    r_toe: float = 0.004                # [m] toe sphere radius
    hip_armature: float = ROTOR_INERTIA * GEAR ** 2
    hip_damping: float = GEAR_VISCOUS * GEAR ** 2
    hip_frictionloss: float = 0.0       # [N m]
    contact_solref: tuple = (0.002, 1.0)
    contact_solimp: tuple = (0.9, 0.95, 0.001, 0.5, 2.0)
    friction: float = 1.0
    floor_tilt: float = 0.0             # [rad] the floor plane tilted about the world x axis
    floor_tilt_dir: float = 0.0         # [rad] azimuth of the tilt's uphill direction
    limit_solref: tuple = (0.0005, 1.0)  # the leg's stopper
    timestep: float = 2.5e-4
    integrator: str = "RK4"
    words: tuple = field(default=())

    def but(self, **kw) -> "Variant":
        return replace(self, **kw)


def _f(x) -> str:
    return " ".join(f"{v:.10g}" for v in np.atleast_1d(x))


def build_mjcf(v: Variant, p: Nominal | None = None) -> str:
    p = p or load_nominal()
    m_tot = v.m_body + v.m_leg + v.m_toe
    g_solref, g_solimp = _f(v.contact_solref), _f(v.contact_solimp)
    if v.boom == "hinge":
        boom_open = f"""
    <body name="boom" pos="0 0 {Z_PIVOT}">
      <joint name="azimuth" type="hinge" axis="0 0 1" damping="{p.d_h * m_tot * R_AZ ** 2:.10g}"/>
      <joint name="elevation" type="hinge" axis="0 -1 0" damping="{p.d_v * m_tot * R_ELEV ** 2:.10g}"/>
      <inertial pos="{R_ELEV / 2} 0 0" mass="1e-4" diaginertia="1e-6 1e-6 1e-6"/>
      <body name="tip" pos="{R_ELEV} 0 0">
        <joint name="level" type="hinge" axis="0 -1 0"/>
        <inertial pos="0 0 0" mass="1e-4" diaginertia="1e-6 1e-6 1e-6"/>
        <body name="body" pos="{LEG_OFFSET} 0 0">"""
        boom_close = """
        </body>
      </body>
    </body>"""
        equality = """
  <equality>
    <joint name="four_bar" joint1="level" joint2="elevation" polycoef="0 -1 0 0 0"
           solref="0.0005 1" solimp="0.99 0.999 0.001 0.5 2"/>
  </equality>"""
    elif v.boom == "planar":
        boom_open = f"""
    <body name="body" pos="0 0 0">
      <joint name="y" type="slide" axis="0 1 0" damping="{p.d_h * m_tot:.10g}"/>
      <joint name="z" type="slide" axis="0 0 1" damping="{p.d_v * m_tot:.10g}"/>"""
        boom_close = """
    </body>"""
        equality = ""
    else:
        raise ValueError(v.boom)
    # floor: a plane; tilted about a horizontal axis when floor_tilt != 0
    if v.floor_tilt:
        ax = (-math.sin(v.floor_tilt_dir), math.cos(v.floor_tilt_dir), 0.0)
        floor_rot = f'axisangle="{_f(ax)} {-v.floor_tilt:.10g}"'
    else:
        floor_rot = ""
    toe_centre = p.rho0 - v.r_toe
    xml = f"""
<mujoco model="{v.name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{v.timestep}" integrator="{v.integrator}" gravity="0 0 {-p.g}"/>
  <default>
    <geom contype="0" conaffinity="0"/>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" {floor_rot} contype="1" conaffinity="1"
          friction="{v.friction} 0.005 0.0001" solref="{g_solref}" solimp="{g_solimp}"/>{boom_open}
          <inertial pos="0 0 0" mass="{v.m_body}" diaginertia="0.01 0.01 0.01"/>
          <geom name="body_geom" type="box" size="0.06 0.04 0.03" mass="0"/>
          <body name="leg" pos="0 0 0">
            <joint name="hip" type="hinge" axis="1 0 0" armature="{v.hip_armature:.10g}"
                   damping="{v.hip_damping:.10g}" frictionloss="{v.hip_frictionloss:.10g}"/>
            <inertial pos="0 0 {-v.r_leg}" mass="{max(v.m_leg, 1e-6):.10g}"
                      diaginertia="{max(v.i_leg, 1e-9):.10g} {max(v.i_leg, 1e-9):.10g} {max(v.i_leg, 1e-9) * 0.1:.10g}"/>
            <body name="toe" pos="0 0 {-toe_centre:.10g}">
              <joint name="leg" type="slide" axis="0 0 -1" stiffness="{p.k}" springref="0"
                     damping="{p.d}" range="-0.12 0" solreflimit="{_f(v.limit_solref)}"
                     solimplimit="0.95 0.99 0.001 0.5 2"/>
              <geom name="toe" type="sphere" size="{v.r_toe}" mass="{v.m_toe}" contype="1"
                    conaffinity="1" condim="3" friction="{v.friction} 0.005 0.0001"
                    solref="{g_solref}" solimp="{g_solimp}"/>
            </body>
          </body>{boom_close}
  </worldbody>{equality}
  <actuator>
    <motor name="hip_motor" joint="hip" gear="1" ctrlrange="{-TORQUE_LIMIT:.6g} {TORQUE_LIMIT:.6g}"/>
  </actuator>
</mujoco>
"""
    return xml


class Robot:
    """A MuJoCo model of the hopper with state accessors in the plant's conventions."""

    def __init__(self, v: Variant, p: Nominal | None = None):
        self.v = v
        self.p = p or load_nominal()
        self.xml = build_mjcf(v, self.p)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        jid = {n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)
               for n in ("azimuth", "elevation", "level", "y", "z", "hip", "leg")}
        self.qa = {n: (int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])) for n, j in jid.items()
                   if j >= 0}
        self.toe_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "toe")
        self.toe_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "toe")
        self.body_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "body")
        self.hinge = v.boom == "hinge"

    # ---- state in the plant's conventions
    def q(self, n):
        return self.data.qpos[self.qa[n][0]]

    def qd(self, n):
        return self.data.qvel[self.qa[n][1]]

    def set_state(self, y, z, vy, vz, theta, thetad=0.0):
        d = self.data
        mujoco.mj_resetData(self.model, d)
        if self.hinge:
            psi = math.asin((z - Z_PIVOT) / R_ELEV)
            d.qpos[self.qa["azimuth"][0]] = y / R_AZ
            d.qpos[self.qa["elevation"][0]] = psi
            d.qpos[self.qa["level"][0]] = -psi
            d.qvel[self.qa["azimuth"][1]] = vy / R_AZ
            d.qvel[self.qa["elevation"][1]] = vz / (R_ELEV * math.cos(psi))
            d.qvel[self.qa["level"][1]] = -vz / (R_ELEV * math.cos(psi))
        else:
            d.qpos[self.qa["y"][0]] = y
            d.qpos[self.qa["z"][0]] = z
            d.qvel[self.qa["y"][1]] = vy
            d.qvel[self.qa["z"][1]] = vz
        d.qpos[self.qa["hip"][0]] = theta
        d.qvel[self.qa["hip"][1]] = thetad
        # the leg held at its stopper against the toe's weight
        d.qpos[self.qa["leg"][0]] = 0.0
        mujoco.mj_forward(self.model, d)

    def angles(self):
        """Encoder axes: (azimuth, elevation, leg angle) [rad]; planar: (y, z, theta)."""
        if self.hinge:
            return self.q("azimuth"), self.q("elevation"), self.q("hip")
        return self.q("y"), self.q("z"), self.q("hip")

    def yz(self):
        if self.hinge:
            psi = self.q("elevation")
            return (R_AZ * self.q("azimuth"), Z_PIVOT + R_ELEV * math.sin(psi),
                    R_AZ * self.qd("azimuth"), R_ELEV * math.cos(psi) * self.qd("elevation"))
        return self.q("y"), self.q("z"), self.qd("y"), self.qd("z")

    def theta(self):
        return self.q("hip"), self.qd("hip")

    def rho(self):
        return self.p.rho0 + self.q("leg"), self.qd("leg")

    def toe_contact(self):
        """(in contact, normal force [N]) of the toe against the floor."""
        d = self.data
        f = np.zeros(6)
        force, touch = 0.0, False
        for i in range(d.ncon):
            c = d.contact[i]
            if c.geom1 == self.toe_geom or c.geom2 == self.toe_geom:
                if c.dist < 0 or c.efc_address >= 0:
                    mujoco.mj_contactForce(self.model, d, i, f)
                    force += f[0]
                    touch = touch or f[0] > 0
        return touch, force

    def hip_inertia(self):
        """The hip's diagonal of the mass matrix (leg + toe + armature) [kg m^2]."""
        M = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, M)
        i = self.qa["hip"][1]
        return float(M[i, i])

    def energy(self):
        """Kinetic + gravitational + leg spring energy [J] (mjENBL_ENERGY must be on)."""
        return float(self.data.energy[0] + self.data.energy[1])

    def step(self, tau):
        self.data.ctrl[0] = tau
        mujoco.mj_step(self.model, self.data)
