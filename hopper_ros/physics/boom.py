"""Effective gravity on a leg carried at the tip of the boom, section 4.3.1.1, (4.5)-(4.7).

The boom pivots about its base; a point mass M (leg structure, m_b + m_t) at its tip of
length L and the boom's own mass m_boom (a uniform rod, I_boom = m_boom L^2 / 3) give, for
small boom angles (cos psi ~ 1, z = L psi):

    (I_boom + M L^2) psi'' = -M L g0 - m_boom L g0 / 2                           (4.6)
    z'' = -g0 (M + m_boom/2) / (M + m_boom/3)                                  (4.7)

Inconsistency in the seed: with its stated masses (M = 2.22 kg, m_boom = 0.39 kg) (4.7)
gives 10.08 m/s^2, not the 11.41 m/s^2 it reports; (4.7) itself follows correctly from
(4.6). Reaching 11.41 m/s^2 would need m_boom ~= 1.45 M ~= 3.2 kg. The boom alone therefore
explains about a sixth of the identified g - g0 = 1.61 m/s^2 (Table 4.1); the model keeps the
identified g as its parameter (config/model.yaml) and this function serves to reason about
the boom's share (the simulated robot of a later issue offers it as a switchable effect).
"""

from __future__ import annotations

STANDARD_GRAVITY = 9.81  # g0 [m/s^2], as in the thesis


def boom_effective_gravity(leg_mass: float, boom_mass: float, standard_gravity: float = STANDARD_GRAVITY) -> float:
    """Vertical acceleration of the leg in free fall at the boom tip, (4.7) [m/s^2]."""
    if leg_mass <= 0.0 or boom_mass < 0.0:
        raise ValueError(f"leg_mass must be positive and boom_mass non-negative, got {leg_mass}, {boom_mass}")
    return standard_gravity * (leg_mass + boom_mass / 2.0) / (leg_mass + boom_mass / 3.0)


def boom_mass_for_gravity(leg_mass: float, effective_gravity: float, standard_gravity: float = STANDARD_GRAVITY) -> float:
    """The boom mass that (4.7) needs to produce `effective_gravity` [kg]."""
    ratio = effective_gravity / standard_gravity
    if not 1.0 <= ratio < 1.5:
        raise ValueError(f"(4.7) gives between 1 and 1.5 g0; {effective_gravity} m/s^2 is out of reach")
    return leg_mass * (ratio - 1.0) / (0.5 - ratio / 3.0)
