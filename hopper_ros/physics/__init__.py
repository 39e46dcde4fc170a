"""Extended TD-SLIP model of the boom-mounted one-legged hopper (Orhon 2018, chapter 2).

Plain Python (numpy/scipy), no ROS import. One place for the model:

- `params`      parameter set (Table 4.1), YAML load/save, validation
- `flight`      closed-form flight with flight damping, (2.13)-(2.16)
- `exact`       exact hybrid model: stance (2.9) integrated numerically, events by root finding
- `aas`         approximate analytical solution and the apex return map (2.3)-(2.37)
- `energy`      energy terms of the deadbeat controller, (5.1)-(5.5), corrected
- `metrics`     prediction errors E_p, E_v, E_t and the cost C, (4.1)-(4.4)
- `boom`        effective gravity of the boom, (4.5)-(4.7)
- `evaluation`  predictors against the exact model on strides from the thesis ranges

Conventions (used everywhere in this package, stated once here):

- SI units inside: m, s, kg, rad, N, N m. Degrees only at the edges (CLI, reports).
- y is the forward position (the running direction, positive forward speed), z the body
  height above the ground (ground at z = 0).
- theta is the leg angle from the vertical, positive when the toe is ahead of the body. In
  stance the body sits at (y_toe - rho sin(theta), rho cos(theta)); running forward the leg
  touches down with theta_td > 0 and sweeps to theta_lo < 0, so theta_dot < 0 in stance.
- tau is the hip torque on the leg, positive when it increases theta, as in (2.9). The stance
  ramp (2.32) is applied with the sign the thesis used on the robot (section 4.1, "multiplied
  by -1"): tau(t) = -tau_0 (1 - t/t_f), so a positive tau_0 pushes the body forward and
  injects energy when running forward. t is measured from touchdown.
- A stride runs from one apex to the next. Stride quantities (next-apex forward position,
  stride time) are measured from the stride's opening apex.
"""
