"""Where the mismatch tool looks: one registry of sites, each with what every part of the tool needs of it.

A site is a phase and a direction where a residual is measured (`locate`), a term library is regressed
(`discover`, with the `physics.laws` field its coefficients set), re-simulated channels are attributed
(`locate.trajectory_location`), a position channel's ringing shows (`ringing`), and library effects act
(`effect_sites`). A new site or term library is added here and in `physics.laws`, nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass

from hopper_ros.physics import laws


@dataclass(frozen=True)
class Site:
    name: str
    phase: str                 # in words: flight, stance, touchdown, lift-off
    direction: str             # in words
    unit: str                  # of its residual
    bins: tuple                # the windows its residual is averaged over, per stride
    terms: object = None       # the laws.TermLibrary regressed there (None: no residual samples)
    field: str = ""            # the laws.Coefficients field of those terms' coefficients
    context: str = ""          # what a term there depends on: flight | stance | jump
    trajectory: tuple = ()     # (phase, channel) of the re-simulated strides that belong to it
    ringing_channel: str = ""  # the position channel whose ringing after lift-off shows here


FLIGHT_BINS, STANCE_BINS = ("descent", "ascent"), ("early stance", "mid stance", "late stance")
SITES: tuple[Site, ...] = (
    Site("flight_horizontal", "flight", "horizontal", "N", FLIGHT_BINS, laws.FLIGHT_Y_TERMS, "flight_y_terms",
         "flight", (("descent", "y"), ("ascent", "y")), "y"),
    Site("flight_vertical", "flight", "vertical", "N", FLIGHT_BINS, laws.FLIGHT_Z_TERMS, "flight_z_terms",
         "flight", (("descent", "z"), ("ascent", "z")), "z"),
    Site("stance_along", "stance", "along the leg", "N", STANCE_BINS, laws.LEG_TERMS, "leg_terms", "stance",
         (("compression", "y"), ("compression", "z"), ("decompression", "y"), ("decompression", "z"))),
    Site("stance_hip", "stance", "about the hip", "N m", STANCE_BINS, laws.HIP_TERMS, "hip_terms", "stance",
         (("compression", "theta"), ("decompression", "theta"))),
    Site("touchdown_along", "touchdown", "along the leg", "m/s", ("at touchdown",), laws.JUMP_TERMS,
         "touchdown_along_terms", "jump"),
    Site("touchdown_across", "touchdown", "across the leg", "m/s", ("at touchdown",), laws.JUMP_TERMS,
         "touchdown_across_terms", "jump"),
    Site("liftoff_along", "lift-off", "along the leg", "m/s", ("at lift-off",), laws.JUMP_TERMS,
         "liftoff_along_terms", "jump", (("liftoff", "y"), ("liftoff", "z"))),
    Site("liftoff_across", "lift-off", "across the leg", "m/s", ("at lift-off",), laws.JUMP_TERMS,
         "liftoff_across_terms", "jump"),
)
# located from the events' timing, not from residual samples (no terms there)
TOUCHDOWN_TIMING = Site("touchdown_timing", "touchdown", "in time", "ms", ("stance begins early", "stance begins late"))

REGISTRY: dict[str, Site] = {s.name: s for s in SITES + (TOUCHDOWN_TIMING,)}
RESIDUAL_SITES: tuple[str, ...] = tuple(s.name for s in SITES)       # with residual samples and terms
TRAJECTORY_SITES = {pc: s.name for s in SITES for pc in s.trajectory}
CHANNEL_SITE = {s.ringing_channel: s.name for s in SITES if s.ringing_channel}

# a library effect (physics.effects: its site, and its direction where it has one) -> the sites where it acts
_BY_EFFECT_SITE = {
    "flight": ("flight_horizontal", "flight_vertical"),
    "touchdown": ("touchdown_along", "touchdown_across", "touchdown_timing"),
    "stance_leg": ("stance_along",), "stance_hip": ("stance_hip",), "actuator": ("stance_hip",),
    "liftoff": ("liftoff_along", "liftoff_across"), "sensor": (),
}
_BY_EFFECT_DIRECTION = {
    ("flight", "horizontal"): ("flight_horizontal",), ("flight", "vertical"): ("flight_vertical",),
    ("flight", "both"): ("flight_horizontal", "flight_vertical"),
    ("touchdown", "along"): ("touchdown_along",), ("touchdown", "across"): ("touchdown_across",),
    ("touchdown", "vertical"): ("touchdown_timing",),
    ("stance_leg", "along"): ("stance_along",), ("stance_leg", "horizontal"): ("stance_along", "stance_hip"),
    ("liftoff", "both"): ("liftoff_along", "liftoff_across"),
    ("stance_hip", "hip, across at touchdown"): ("stance_hip", "touchdown_across"),
}


def effect_sites(effect_site: str, direction: str = "") -> tuple[str, ...]:
    """The sites where a library effect acting at `effect_site` (in `direction`) changes the motion."""
    return _BY_EFFECT_DIRECTION.get((effect_site, direction), _BY_EFFECT_SITE[effect_site])


def first_sites(effect_site: str) -> tuple[str, ...]:
    """The sites where any effect of a library site shows first (the screening keeps those located)."""
    return _BY_EFFECT_SITE[effect_site]


def hinge_of(field: str):
    """(term key, knot field) of the hinge term in the library of Coefficients field `field`, or None."""
    return laws.HINGES.get(field[:-len("_terms")])
