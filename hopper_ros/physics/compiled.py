"""The lanes integrator compiled by numba from the laws of `physics.laws` (the same functions, no copy).

`laws` is written for floats and arrays alike; numba compiles those functions for one lane's floats
(`register_jitable`), with the scalar forms of laws' few array helpers overloaded here (`where`, `clip`,
`ones_like`, `nan_to_num`, `nonzero`, `is_on`). A lane's `Coefficients` is one record of a structured
array whose fields are the dataclass's (`record_dtype`, with a flag per `*_terms` field: its gate), so
`c.stiffness` reads the same in both.

`integrate` steps every lane on its own, exactly as `physics.lanes` steps them together (RK4 at h, a
flight's sample in one step where no event falls in it, the guard's sign change located by linear
interpolation and the step split there, collapse and tipping checks after each step), so the two paths
agree to rounding. A lane that has fallen keeps its state, and its remaining samples are copied instead
of integrated; a lane given a number of `needed` samples stops once it has them and has found its next
apex (or fallen), its later samples nan.

`compile_kernels` compiles other modules' functions written the same way (the simulated robot's step,
`hopper_ros.sim.plant`) with these laws.

Compiled code is cached on disk (`cache_directory`), in a folder named by a hash of the sources it is
compiled from (numba alone would check only this file's time stamp, not the laws').
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from pathlib import Path

import numba
import numpy as np
from numba.core import types
from numba.core.errors import TypingError
from numba.extending import overload, register_jitable

from . import laws
from .exact import COLLAPSE_FRACTION, MAX_LEG_ANGLE

DESCENT, STANCE, ASCENT, DEAD = 0, 1, 2, 3
STATE = 9          # y, z, ydot, zdot, depth, applied torque (lag state), toe y, the leg's hysteresis state, its
#                    relaxing force


def _sources_hash() -> str:
    digest = hashlib.sha256(numba.__version__.encode())
    for name in ("compiled.py", "laws.py", "broadcast.py", "terms.py", "exact.py"):
        digest.update((Path(__file__).parent / name).read_bytes())
    return digest.hexdigest()[:16]


def cache_directory() -> Path:
    """Where the compiled code is kept: $NUMBA_CACHE_DIR if set, else the user's cache folder; where that cannot be
    written (a read-only home), the temporary folder."""
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "hopper_ros", "numba")
    for folder in (Path(base), Path(tempfile.gettempdir()) / f"hopper_ros-numba-{os.getuid()}"):
        try:
            (folder / _sources_hash()).mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(folder / _sources_hash(), os.W_OK):
            return folder / _sources_hash()
    raise ImportError(f"no folder to keep compiled code in ({base} cannot be written)")


numba.config.CACHE_DIR = str(cache_directory())


# ---------------------------------------------------------------------------- laws' helpers on floats


@overload(laws.where)
def _where(condition, if_true, if_false):
    return lambda condition, if_true, if_false: if_true if condition else if_false


@overload(laws.clip)
def _clip(value, low, high):
    return lambda value, low, high: min(max(value, low), high)


@overload(laws.ones_like)
def _ones_like(value):
    return lambda value: 1.0


@overload(laws.nan_to_num)
def _nan_to_num(value):
    def impl(value):
        if np.isnan(value):
            return 0.0
        if np.isinf(value):
            return np.finfo(np.float64).max if value > 0 else -np.finfo(np.float64).max
        return value
    return impl


@overload(laws.nonzero)
def _nonzero(coefficient):
    return lambda coefficient: coefficient != 0.0


def _gate(name: str):
    """The compiled `is_on(c, name)`: the lane's coefficient is not off."""
    if name.endswith("_terms"):
        source = f"def gate(c, name):\n    return c.{name}_on\n"      # any of its coefficients not 0 (`records`)
    elif name == "ground_friction":
        source = "def gate(c, name):\n    return np.isfinite(c.ground_friction)\n"
    else:
        source = f"def gate(c, name):\n    return c.{name} != 0.0\n"
    namespace = {"np": np}
    exec(source, namespace)      # one small function per field name (numba compiles from the bytecode)
    return namespace["gate"]


_GATES = {name: _gate(name) for name in laws.GATED + ("ground_friction",) + laws.Coefficients.term_names()}


@overload(laws.is_on, prefer_literal=True)
def _is_on(c, name):
    if not isinstance(name, types.StringLiteral) or name.literal_value not in _GATES:
        raise TypingError(f"is_on: a literal coefficient name is needed, got {name}")
    return _GATES[name.literal_value]


for _law in (laws.ramp_torque, laws.smooth_sign, laws.flight_y_term, laws.flight_z_term, laws.leg_term,
             laws.hip_term, laws.jump_term, laws.sum_terms, laws.boom_sphere, laws.flight_acceleration,
             laws.stance_context,
             laws.leg_force, laws.hysteresis_rate, laws.relaxation_rate, laws.hip_losses, laws.voltage_limited,
             laws.speed_derated, laws.servo_hold,
             laws.rotor_torque,
             laws.stance_forces,
             laws.toe_slip_rate,
             laws.actuator_torque, laws._leg_components, laws._from_components, laws.rotor_spin_up,
             laws.touchdown_velocity, laws.liftoff_velocity, laws.touchdown_height, laws.foot_rise,
             laws.foot_at_touchdown, laws.foot_offset):
    register_jitable(_law)


# ---------------------------------------------------------------------------- coefficients as records


def record_dtype() -> np.dtype:
    """One float per scalar field of `laws.Coefficients`, a float array per `*_terms` field, and per `*_terms` field
    a flag `<name>_on`: whether any of its coefficients is not 0 (its gate, read once per lane instead of per law)."""
    base = laws.Coefficients()
    return np.dtype([(name, np.float64) for name in laws.Coefficients.scalar_names()]
                    + [(name, np.float64, (len(getattr(base, name)),)) for name in laws.Coefficients.term_names()]
                    + [(f"{name}_on", np.bool_) for name in laws.Coefficients.term_names()])


RECORD = record_dtype()


def records(c: laws.Coefficients, n: int) -> np.ndarray:
    """The lanes of `c` (fields floats or arrays of n) as n records."""
    out = np.empty(n, dtype=RECORD)
    for name in laws.Coefficients.scalar_names():
        out[name] = getattr(c, name)
    for name in laws.Coefficients.term_names():
        for i, value in enumerate(getattr(c, name)):
            out[name][:, i] = value
        out[f"{name}_on"] = np.any(out[name] != 0.0, axis=1)
    return out


# ---------------------------------------------------------------------------- one lane
# The state is a tuple of STATE floats (kept in registers); `_evaluate` gives its rate and the guard of the
# mode's next event from one evaluation of the laws, so a step that ends without an event hands both to the next.


@numba.njit(cache=True, error_model="numpy", inline="always")
def _axpy(s, a, k):
    return (s[0] + a * k[0], s[1] + a * k[1], s[2] + a * k[2], s[3] + a * k[3], s[4] + a * k[4], s[5] + a * k[5],
            s[6] + a * k[6], s[7] + a * k[7], s[8] + a * k[8])


@numba.njit(cache=True, error_model="numpy", inline="always")
def _evaluate(c, t, s, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag, compliant):
    """(the state's rate, the guard: positive before the mode's next event, <= 0 at it). `ground_clearance`: the
    body height at which the held leg touches down (`laws.touchdown_height`, constant over a flight)."""
    if mode == STANCE:
        command = laws.ramp_torque(t - c.torque_delay - t_td, tau_0, t_f)
        target = laws.actuator_torque(c, command)
        applied = s[5] if lagged else target
        f = laws.stance_forces(c, s[0], s[1], s[2], s[3], s[4], s[6], applied, command, theta_at_td, t - t_td,
                               compliant, s[7], s[8])
        lag_rate = (target - s[5]) / lag if lagged else 0.0
        return ((s[2], s[3], f.ydd, f.zdd, f.depth_rate, lag_rate, f.toe_rate, f.hysteresis_rate,
                 f.relaxation_rate),
                np.minimum(f.force, c.rest_length - f.rho))
    if mode == DEAD:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), np.inf
    ay, az = laws.flight_acceleration(c, s[0], s[1], s[2], s[3])
    if mode == DESCENT:
        guard = s[1] - ground_clearance
    elif not apex_found:
        guard = s[3]
    else:
        guard = np.inf
    return (s[2], s[3], ay, az, 0.0, 0.0, 0.0, 0.0, 0.0), guard


@numba.njit(cache=True, error_model="numpy", inline="always")
def _rk4(c, t, s, k1, h, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag, compliant):
    """One RK4 step from s (whose rate is k1)."""
    k2, _ = _evaluate(c, t + 0.5 * h, _axpy(s, 0.5 * h, k1), mode, apex_found, ground_clearance, t_td, tau_0, t_f,
                      theta_at_td, lagged, lag, compliant)
    k3, _ = _evaluate(c, t + 0.5 * h, _axpy(s, 0.5 * h, k2), mode, apex_found, ground_clearance, t_td, tau_0, t_f,
                      theta_at_td, lagged, lag, compliant)
    k4, _ = _evaluate(c, t + h, _axpy(s, h, k3), mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td,
                      lagged, lag, compliant)
    w = h / 6.0
    return (s[0] + w * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]), s[1] + w * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]),
            s[2] + w * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]), s[3] + w * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3]),
            s[4] + w * (k1[4] + 2 * k2[4] + 2 * k3[4] + k4[4]), s[5] + w * (k1[5] + 2 * k2[5] + 2 * k3[5] + k4[5]),
            s[6] + w * (k1[6] + 2 * k2[6] + 2 * k3[6] + k4[6]), s[7] + w * (k1[7] + 2 * k2[7] + 2 * k3[7] + k4[7]),
            s[8] + w * (k1[8] + 2 * k2[8] + 2 * k3[8] + k4[8]))


TIP_SLOPE = (1.0 - 1e-6) * math.tan(MAX_LEG_ANGLE)    # |dy| below TIP_SLOPE hz: the leg well inside MAX_LEG_ANGLE


@numba.njit(cache=True, error_model="numpy", inline="always")
def _tipped(dy, hz):
    """|arctan2(-dy, hz)| > MAX_LEG_ANGLE (the body tipped over), arctan2 skipped where the leg is clearly inside it
    (a margin of 1e-6 of the slope, far beyond arctan2's rounding: the same answer in every case)."""
    if hz > 0.0 and np.abs(dy) < TIP_SLOPE * hz:
        return False
    return np.abs(np.arctan2(-dy, hz)) > MAX_LEG_ANGLE


@numba.njit(cache=True, error_model="numpy")
def _record(c, s, mode, theta_hold, out, lane, j):
    if mode == STANCE:
        dy, hz = laws.foot_offset(c, s[0], s[1], s[4], s[6])
        theta = np.arctan2(-dy, hz)
    else:
        theta = theta_hold
    out[0, lane, j], out[1, lane, j], out[2, lane, j] = s[0], s[1], theta
    out[3, lane, j], out[4, lane, j] = s[2], s[3]


@numba.njit(cache=True, error_model="numpy")
def _lane(c, lane, apex_height, forward_speed, theta_td, tau_0, ramp_duration, h, steps_per_sample, samples,
          needed, out, apex, events, fell):
    s = (0.0, apex_height, forward_speed, 0.0, 0.0, 0.0, np.nan, 0.0, 0.0)
    theta_hold = theta_at_td = theta_td
    t_f = max(ramp_duration, 1e-6)
    lagged = c.torque_lag > 0
    lag = c.torque_lag if lagged else 1.0
    compliant = c.ground_stiffness > 0
    ground_clearance = laws.touchdown_height(c, theta_hold)
    mode = DESCENT
    t_td = t_lo = np.nan
    apex_found = False
    t = 0.0
    k, g = _evaluate(c, t, s, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag, compliant)
    _record(c, s, mode, theta_hold, out, lane, 0)
    for j in range(1, samples):
        if j >= needed and (apex_found or mode == DEAD):     # nothing more is read
            out[:, lane, j:] = np.nan
            break
        if mode == DEAD:             # the state holds: its samples repeat
            for q in range(5):
                out[q, lane, j] = out[q, lane, j - 1]
            continue
        if mode == DESCENT or mode == ASCENT:       # a flight's sample in one step, where no event falls in it
            big = h * steps_per_sample
            s1 = _rk4(c, t, s, k, big, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag,
                      compliant)
            k1, g1 = _evaluate(c, t + big, s1, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td,
                               lagged, lag, compliant)
            if not (g > 0 and g1 <= 0 and np.isfinite(g)):
                s, k, g = s1, k1, g1
                for _ in range(steps_per_sample):
                    t += h
                _record(c, s, mode, theta_hold, out, lane, j)
                continue
        for _ in range(steps_per_sample):
            s1 = _rk4(c, t, s, k, h, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag,
                      compliant)
            k1, g1 = _evaluate(c, t + h, s1, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged,
                               lag, compliant)
            changed = False
            if g > 0 and g1 <= 0 and np.isfinite(g):
                hh = min(max(g / (g - g1), 0.0), 1.0) * h
                s1 = _rk4(c, t, s, k, hh, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag,
                          compliant)
                te = t + hh
                new_mode = mode
                if mode == DESCENT:
                    vy, vz = laws.touchdown_velocity(c, theta_hold, s1[2], s1[3])
                    t_td = te
                    theta_at_td = theta_hold
                    s1 = (s1[0], s1[1], vy, vz, 0.0, 0.0, laws.foot_at_touchdown(c, s1[0], theta_hold), 0.0,
                          0.0)
                    new_mode = STANCE
                elif mode == STANCE:
                    dy, hz = laws.foot_offset(c, s1[0], s1[1], s1[4], s1[6])
                    theta_lo = np.arctan2(-dy, hz)
                    vy, vz = laws.liftoff_velocity(c, theta_lo, s1[2], s1[3])
                    theta_hold = theta_lo
                    ground_clearance = laws.touchdown_height(c, theta_hold)
                    t_lo = te
                    s1 = (s1[0], s1[1], vy, vz, 0.0, s1[5], s1[6], s1[7], s1[8])
                    new_mode = ASCENT if s1[3] > 0 else DEAD
                elif mode == ASCENT:
                    apex[0, lane], apex[1, lane], apex[2, lane], apex[3, lane] = te, s1[0], s1[1], s1[2]
                    apex_found = True
                mode = new_mode
                ke, _ = _evaluate(c, te, s1, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged,
                                  lag, compliant)
                s1 = _rk4(c, te, s1, ke, h - hh, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged,
                          lag, compliant)
                changed = True
            s = s1
            t += h
            if mode == STANCE:       # collapse or tipping: the stride failed
                dy, hz = laws.foot_offset(c, s[0], s[1], s[4], s[6])
                rho = np.sqrt(dy * dy + hz * hz) + c.foot_radius
                if rho < COLLAPSE_FRACTION * c.rest_length or _tipped(dy, hz):
                    mode = DEAD
                    changed = True
            if changed:
                k, g = _evaluate(c, t, s, mode, apex_found, ground_clearance, t_td, tau_0, t_f, theta_at_td, lagged, lag,
                                 compliant)
            else:
                k, g = k1, g1
        _record(c, s, mode, theta_hold, out, lane, j)
    events[0, lane], events[1, lane] = t_td, t_lo
    fell[lane] = mode == DEAD


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _lanes(c, apex_height, forward_speed, theta_td, tau_0, ramp_duration, h, steps_per_sample, samples, needed,
           out, apex, events, fell):
    for lane in numba.prange(c.shape[0]):
        _lane(c[lane], lane, apex_height[lane], forward_speed[lane], theta_td[lane], tau_0[lane],
              ramp_duration[lane], h, steps_per_sample, samples, needed[lane], out, apex, events, fell)


def integrate(c: laws.Coefficients, apex_height, forward_speed, theta_td, tau_0, ramp_duration, h: float,
              steps_per_sample: int, samples: int, needed=None):
    """Every lane from its apex for `samples` samples of `steps_per_sample` RK4 steps of `h` (`needed`: per lane,
    the samples read; later ones are nan once the lane has found its next apex).

    Returns (out (5, lanes, samples) float32: y, z, theta, y', z'; apex (4, lanes): t, y, z, y' of the next
    apex; events (2, lanes): touchdown and lift-off times; fell (lanes,) bool).
    """
    n = len(apex_height)
    lanes = records(c, n)
    out = np.empty((5, n, samples), dtype=np.float32)
    apex = np.full((4, n), np.nan)
    events = np.full((2, n), np.nan)
    fell = np.zeros(n, dtype=np.bool_)
    columns = [np.ascontiguousarray(np.broadcast_to(np.asarray(x, dtype=np.float64), (n,)))
               for x in (apex_height, forward_speed, theta_td, tau_0, ramp_duration)]
    needed = np.full(n, samples, dtype=np.int64) if needed is None else np.asarray(needed, dtype=np.int64)
    _lanes(lanes, *columns, float(h), int(steps_per_sample), int(samples), needed, out, apex, events, fell)
    return out, apex, events, fell


# ---------------------------------------------------------------------------- kernels written elsewhere like the laws


def compile_kernels(entries, helpers=()):
    """`entries` compiled by numba (cached on disk with the lanes): functions written like the laws, for one set of
    floats, that call `laws` and `helpers` (functions of their own module written the same way, compiled where they
    are called); their coefficients are records (`records`). Returns the compiled entries, in order.

    numba checks an entry's own file for changes; the laws' and this module's are in the cache folder's name.
    """
    for helper in helpers:
        register_jitable(helper)
    return [numba.njit(cache=True, error_model="numpy")(entry) for entry in entries]
