"""Closed-form flight (2.13)-(2.16) against numerical integration of (2.8)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hopper_ros.physics import laws
from hopper_ros.physics.flight import apex_time, descent_time, flight_state

G = 11.42


@pytest.mark.parametrize("damping_h, damping_v, tolerance", [
    (0.01, 0.23, 1e-10), (0.0, 0.0, 1e-10), (0.5, 1.2, 1e-10),
    (1e-9, 1e-9, 5e-9),  # below NEGLIGIBLE_DAMPING: the ballistic limit, off by ~g d t^2 / 2
])
def test_closed_form_flight_equals_integrated_flight(damping_h, damping_v, tolerance):
    def rhs(t, s):
        return [s[2], s[3], -damping_h * s[2], -G - damping_v * s[3]]

    times = np.linspace(0.0, 0.5, 26)
    start = [0.1, 0.3, 2.0, 1.5]
    integrated = solve_ivp(rhs, (0.0, 0.5), start, t_eval=times, rtol=1e-12, atol=1e-14).y
    closed = np.array(flight_state(times, *start, G, damping_h, damping_v))
    assert np.max(np.abs(closed - integrated)) < tolerance
    # floats take the scalar path and agree with the arrays
    assert np.allclose([flight_state(float(times[7]), *start, G, damping_h, damping_v)], closed[:, 7], atol=1e-15)


@pytest.mark.parametrize("damping_v", [0.23, 0.0])
def test_apex_and_descent_times_solve_their_equations(damping_v):
    t_up = apex_time(1.7, G, damping_v)
    assert flight_state(t_up, 0.0, 0.0, 0.0, 1.7, G, 0.01, damping_v)[3] == pytest.approx(0.0, abs=1e-12)
    drops = np.array([1e-4, 0.05, 0.2, 0.4])
    t_down = descent_time(drops, G, damping_v)
    z = flight_state(t_down, 0.0, 0.5, 1.0, 0.0, G, 0.01, damping_v)[1]
    assert np.allclose(0.5 - z, drops, rtol=0, atol=1e-13)


@pytest.mark.parametrize("z0, zdot0, leg_angle, leg_rate", [(0.36, -2.4, 0.40, 0.3), (0.33, -0.5, 0.25, -1.0),
                                                             (0.40, 1.0, 0.45, 0.0)])
def test_touchdown_time_is_where_the_integrated_flight_meets_the_toe(z0, zdot0, leg_angle, leg_rate):
    from scipy.integrate import solve_ivp

    from hopper_ros.physics.flight import touchdown_time

    g, d_v, rest_length = 11.42, 0.08, 0.34
    t = touchdown_time(z0, zdot0, leg_angle, leg_rate, rest_length, g, d_v)
    toe = lambda t, s: s[0] - rest_length * math.cos(leg_angle + leg_rate * t)  # noqa: E731
    toe.terminal = True
    solved = solve_ivp(lambda t, s: [s[1], -g - d_v * s[1]], [0, 1.0], [z0, zdot0], rtol=1e-12, atol=1e-14, events=toe)
    assert t == pytest.approx(solved.t_events[0][0], abs=1e-9)


@pytest.mark.parametrize("sine", [1.0, 0.0])
@pytest.mark.parametrize("elevation, forward, vertical", [(0.14, 2.0, 1.5), (0.14, 2.0, -1.5), (-0.05, 1.0, 0.5),
                                                         (0.2, 1.5, 1.0)])
def test_the_boom_sphere_law_is_a_body_on_a_sphere_to_the_first_order(elevation, forward, vertical, sine):
    """`laws.boom_sphere` against a point on a sphere of radius R (elevation beta, azimuth phi, gravity g), its
    accelerations from the sphere's own equations: beta'' = -(g/R) cos beta - phi'^2 sin beta cos beta,
    phi'' = 2 tan beta beta' phi', y = R phi, the height z = z_p + R sin beta (hardware.encoders' reading, `sine`
    1) or z = z_p + R beta (read along the arc, 0). The plane's (2.8) misses them by the first order in beta; with
    the law what is left is a tenth of that or less."""
    radius, pivot = 1.65, 0.115
    height_rate = math.cos(elevation) if sine else 1.0          # dz/d(beta) / R
    beta_rate, phi_rate = vertical / (radius * height_rate), forward / radius
    beta_acc = -G / radius * math.cos(elevation) - phi_rate ** 2 * math.sin(elevation) * math.cos(elevation)
    phi_acc = 2.0 * math.tan(elevation) * beta_rate * phi_rate
    vertical_acc = beta_acc * math.cos(elevation) - beta_rate ** 2 * math.sin(elevation) if sine else beta_acc
    exact = (radius * phi_acc, radius * vertical_acc)
    z = pivot + radius * (math.sin(elevation) if sine else elevation)
    plane = laws.Coefficients(gravity=G, flight_damping_y=0.0, flight_damping_z=0.0)
    sphere = plane.replace(boom_curvature=radius ** -2, boom_pivot_height=pivot, boom_sine_reading=sine)
    missed = np.hypot(*np.subtract(laws.flight_acceleration(plane, 0.0, z, forward, vertical), exact))
    left = np.hypot(*np.subtract(laws.flight_acceleration(sphere, 0.0, z, forward, vertical), exact))
    assert missed > 0.01 and left <= 0.1 * missed, (missed, left)
