"""What a device counts of its CiA 301 traffic (the emulated EPOS2's `counters`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Counters:
    malformed_frames: int = 0
    sdo_aborts: int = 0
    emcy_sent: int = 0
    rpdos_applied: int = 0
    tpdos_sent: int = 0
    syncs: int = 0
    syncs_missed: int = 0          # SYNCs that came while the device stood still (never seen: not answered)
