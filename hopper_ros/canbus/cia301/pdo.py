"""A device's PDO engine (CiA 301): 4 RPDOs and 4 TPDOs over the device's object dictionary,
remapped by SDO (the checks a write to a PDO object must pass), the SYNC consumer (synchronous
RPDOs applied and cyclic / acyclic TPDOs sent at a SYNC), event-driven TPDOs (inhibit time,
event timer) and TPDOs on request (RTR).
"""

from __future__ import annotations

import struct
from typing import Any, Callable, NamedTuple

from hopper_ros.canbus import epos2_objects as od
from hopper_ros.canbus.epos2_objects import DATA_TYPE_FORMAT, DataType, SdoAbort

from .counters import Counters
from .sdo_server import SdoRefused
from .values import decode, encode

_MS = 1.0e-3                       # [s/ms]
_INHIBIT_UNIT = 100.0e-6           # [s] unit of the TPDO inhibit time (CiA 301)


class _Pdo(NamedTuple):
    """One PDO as its communication and mapping objects configure it, read once per configuration."""
    cob: int | None                  # None: not valid
    transmission_type: int
    inhibit_time: float              # [s] (TPDO)
    event_timer: float               # [s] (TPDO)
    mapped: tuple                    # (index, subindex) of each mapped object, in order
    entries: tuple                   # the dictionary entry of each (None: dummy mapping)
    layout: struct.Struct | None     # the payload of the mapped values (None: a type without a fixed format)
    length: int                      # [bytes]


def pdo_kind(index: int) -> tuple[str, int, int, int] | None:
    """('RPDO' or 'TPDO', communication index, mapping index, number 0..3) of a PDO object."""
    for kind, comm, mapping in (("RPDO", od.RPDO_COMMUNICATION, od.RPDO_MAPPING),
                                ("TPDO", od.TPDO_COMMUNICATION, od.TPDO_MAPPING)):
        for base in (comm, mapping):
            if base <= index < base + od.PDO_COUNT:
                n = index - base
                return kind, comm + n, mapping + n, n
    return None


class PdoEngine:
    """The PDOs of a device whose dictionary is `table` (entries) and `values` (its current values,
    shared with the device). `operational()` says whether the device is in NMT OPERATIONAL; an RPDO
    goes into the dictionary through `store(entry, value)` (the device's own side effects apply), an
    RPDO of the wrong length is `raise_error(code, now)` (the device's EMCY)."""

    def __init__(self, table: dict, values: dict, send: Callable[[int, bytes], None], counters: Counters,
                 operational: Callable[[], bool], store: Callable[[Any, int | str], None],
                 raise_error: Callable[[int, float], None]) -> None:
        self._table, self._values, self._send, self.counters = table, values, send, counters
        self._operational, self._store, self._raise_error = operational, store, raise_error
        self.reset()

    def reset(self) -> None:
        """Communication reset: SYNC counts, pending RPDOs and the TPDOs' last sends forgotten."""
        self._plans: dict[int, _Pdo] = {}   # communication index -> its configuration (`_pdo`)
        self._sync_counts = [0] * od.PDO_COUNT
        self._pending_rpdos: dict[int, bytes] = {}
        self._tpdo_last_data: list[bytes | None] = [None] * od.PDO_COUNT
        self._tpdo_last_time: list[float | None] = [None] * od.PDO_COUNT

    def cob(self, comm_index: int) -> int | None:
        return self._pdo(comm_index).cob

    def rpdo_number(self, cob: int) -> int | None:
        for n in range(od.PDO_COUNT):
            if self._pdo(od.RPDO_COMMUNICATION + n).cob == cob:
                return n
        return None

    def _pdo(self, comm_index: int) -> _Pdo:
        """The PDO's configuration, read from the dictionary once and kept until a PDO object is written
        (`stored`) or the communication resets: a SYNC then costs one pack or unpack per PDO."""
        plan = self._plans.get(comm_index)
        if plan is None:
            v = self._values
            raw = int(v[(comm_index, od.PDO_COB_ID_SUB)])
            map_index = comm_index - od.RPDO_COMMUNICATION + od.RPDO_MAPPING if comm_index < od.TPDO_COMMUNICATION \
                else comm_index - od.TPDO_COMMUNICATION + od.TPDO_MAPPING
            mapping = self.mapping(map_index)
            entries = tuple(self._table.get((index, sub)) for index, sub, _ in mapping)
            formats = [DATA_TYPE_FORMAT.get(e.data_type) if e is not None else None for e in entries]
            fixed = all(f is not None and struct.calcsize(f) * 8 == bits
                        for f, (_, _, bits) in zip(formats, mapping))
            plan = self._plans[comm_index] = _Pdo(
                cob=None if raw & od.COB_ID_INVALID_BIT else raw & od.COB_ID_MASK_11BIT,
                transmission_type=int(v[(comm_index, od.PDO_TRANSMISSION_TYPE_SUB)]),
                inhibit_time=int(v.get((comm_index, od.PDO_INHIBIT_TIME_SUB), 0)) * _INHIBIT_UNIT,
                event_timer=int(v.get((comm_index, od.PDO_EVENT_TIMER_SUB), 0)) * _MS,
                mapped=tuple((index, sub) for index, sub, _ in mapping), entries=entries,
                layout=struct.Struct("<" + "".join(f.lstrip("<") for f in formats)) if fixed else None,
                length=sum(bits for _, _, bits in mapping) // 8)
        return plan

    def mapping(self, map_index: int) -> list[tuple[int, int, int]]:
        count = int(self._values[(map_index, 0)])
        return [od.split_pdo_mapping_entry(int(self._values[(map_index, s)])) for s in range(1, count + 1)]

    # ---------------------------------------------------------------- RPDOs and SYNC

    def on_rpdo(self, n: int, data: bytes, now: float) -> None:
        if not self._operational():
            return
        pdo = self._pdo(od.RPDO_COMMUNICATION + n)
        if len(data) != pdo.length:
            self.counters.malformed_frames += 1
            self._raise_error(od.ERROR_PDO_LENGTH, now)
            return
        if pdo.transmission_type <= od.TRANSMISSION_SYNC_MAX:
            self._pending_rpdos[n] = data        # applied at the next SYNC
        else:
            self._apply_rpdo(n, data)

    def _apply_rpdo(self, n: int, data: bytes) -> None:
        pdo = self._pdo(od.RPDO_COMMUNICATION + n)
        if pdo.layout is not None:
            for entry, value in zip(pdo.entries, pdo.layout.unpack(data)):
                self._store(entry, value)
            self.counters.rpdos_applied += 1
            return
        offset = 0
        for index, sub, bits in self.mapping(od.RPDO_MAPPING + n):
            size = bits // 8
            chunk = data[offset:offset + size]
            offset += size
            entry = self._table.get((index, sub))
            if entry is None:                    # dummy mapping (data types 0x0001..0x0007)
                continue
            self._store(entry, decode(entry.data_type, chunk))
        self.counters.rpdos_applied += 1

    def on_sync(self, data: bytes, now: float) -> None:
        if len(data) > 1:
            self.counters.malformed_frames += 1
            return
        if not self._operational():
            return
        self.counters.syncs += 1
        for n in sorted(self._pending_rpdos):
            self._apply_rpdo(n, self._pending_rpdos[n])
        self._pending_rpdos.clear()
        for n in range(od.PDO_COUNT):
            pdo = self._pdo(od.TPDO_COMMUNICATION + n)
            if pdo.cob is None:
                continue
            trans = pdo.transmission_type
            if trans == od.TRANSMISSION_SYNC_ACYCLIC:
                payload = self.tpdo_payload(n)
                if payload != self._tpdo_last_data[n]:
                    self._send_tpdo(n, payload, now)
            elif trans <= od.TRANSMISSION_SYNC_MAX:
                self._sync_counts[n] += 1
                if self._sync_counts[n] >= trans:
                    self._sync_counts[n] = 0
                    self._send_tpdo(n, self.tpdo_payload(n), now)

    # ---------------------------------------------------------------- TPDOs

    def tpdo_payload(self, n: int) -> bytes:
        pdo = self._pdo(od.TPDO_COMMUNICATION + n)
        if pdo.layout is not None:
            v = self._values
            return pdo.layout.pack(*[int(v[key]) for key in pdo.mapped])
        out = bytearray()
        for index, sub, bits in self.mapping(od.TPDO_MAPPING + n):
            entry = self._table[(index, sub)]
            out += encode(entry.data_type, self._values[(index, sub)])[: bits // 8]
        return bytes(out)

    def _send_tpdo(self, n: int, payload: bytes, now: float) -> None:
        cob = self._pdo(od.TPDO_COMMUNICATION + n).cob
        if cob is None:
            return
        self._send(cob, payload)
        self._tpdo_last_data[n] = payload
        self._tpdo_last_time[n] = now
        self.counters.tpdos_sent += 1

    def event_tpdos(self, now: float) -> None:
        """Event-driven TPDOs (transmission type 254/255): sent when their data changed (after the
        inhibit time) or their event timer ran out. The device calls it every cycle while operational."""
        for n in range(od.PDO_COUNT):
            pdo = self._pdo(od.TPDO_COMMUNICATION + n)
            if pdo.cob is None or pdo.transmission_type < od.TRANSMISSION_EVENT_MANUFACTURER:
                continue
            last = self._tpdo_last_time[n]
            if last is not None and now - last < pdo.inhibit_time:
                continue
            payload = self.tpdo_payload(n)
            timer = pdo.event_timer
            due = timer > 0 and (last is None or now - last >= timer)
            if payload != self._tpdo_last_data[n] or due:
                self._send_tpdo(n, payload, now)

    def on_remote(self, cob: int, now: float) -> None:
        for n in range(od.PDO_COUNT):
            comm = od.TPDO_COMMUNICATION + n
            raw = int(self._values[(comm, od.PDO_COB_ID_SUB)])
            if self.cob(comm) == cob and not raw & od.COB_ID_NO_RTR_BIT:
                self._send_tpdo(n, self.tpdo_payload(n), now)

    # ---------------------------------------------------------------- remapping by SDO

    def validate(self, entry, value: int | str) -> None:
        """The CiA 301 rules for a write to a PDO object (COB-ID, transmission type, mapping);
        SdoRefused with the abort code. Other objects pass."""
        index, sub = entry.index, entry.subindex
        v = self._values
        pdo = pdo_kind(index)
        if pdo is None:
            return
        kind, comm, mapping, n = pdo
        valid = not int(v[(comm, od.PDO_COB_ID_SUB)]) & od.COB_ID_INVALID_BIT
        if index == comm and sub == od.PDO_COB_ID_SUB:
            old = int(v[(comm, od.PDO_COB_ID_SUB)])
            new_valid = not int(value) & od.COB_ID_INVALID_BIT
            if int(value) & 0x20000000 or (int(value) & 0x1FFFF800):
                raise SdoRefused(SdoAbort.INVALID_VALUE)   # 29-bit identifiers are not supported
            if valid and new_valid and (int(value) ^ old) & od.COB_ID_MASK_11BIT:
                raise SdoRefused(SdoAbort.INVALID_VALUE)   # change the COB-ID only while disabled
        elif index == comm and sub == od.PDO_TRANSMISSION_TYPE_SUB:
            if od.TRANSMISSION_SYNC_MAX < int(value) < od.TRANSMISSION_EVENT_MANUFACTURER:
                raise SdoRefused(SdoAbort.INVALID_VALUE)
        elif index == mapping:
            if valid:
                raise SdoRefused(SdoAbort.UNSUPPORTED_ACCESS)  # disable the PDO first (CiA 301)
            if sub == 0:
                if int(value) > od.PDO_MAX_ENTRIES:
                    raise SdoRefused(SdoAbort.PDO_LENGTH_EXCEEDED)
                entries = [od.split_pdo_mapping_entry(int(v[(mapping, s)])) for s in range(1, int(value) + 1)]
                for e in entries:
                    self._check_mappable(kind, *e)
                if sum(bits for _, _, bits in entries) > 64:
                    raise SdoRefused(SdoAbort.PDO_LENGTH_EXCEEDED)
            else:
                if int(v[(mapping, 0)]) != 0:
                    raise SdoRefused(SdoAbort.UNSUPPORTED_ACCESS)  # set sub 0 to 0 first (CiA 301)
                if int(value) != 0:
                    self._check_mappable(kind, *od.split_pdo_mapping_entry(int(value)))

    def _check_mappable(self, kind: str, index: int, sub: int, bits: int) -> None:
        if kind == "RPDO" and 1 <= index <= 7 and sub == 0:
            size = od.data_type_size(DataType(index)) if index in set(DataType) else None
            if size is None or bits != 8 * size:
                raise SdoRefused(SdoAbort.CANNOT_BE_MAPPED)
            return                                # dummy mapping
        entry = self._table.get((index, sub))
        if entry is None:
            raise SdoRefused(SdoAbort.OBJECT_DOES_NOT_EXIST)
        size = od.data_type_size(entry.data_type)
        usable = entry.access.writable if kind == "RPDO" else entry.access.readable
        if not entry.pdo_mappable or not usable or size is None or bits != 8 * size:
            raise SdoRefused(SdoAbort.CANNOT_BE_MAPPED)

    def stored(self, index: int) -> None:
        """After a PDO object was written: a TPDO sends afresh, an RPDO's pending data is dropped."""
        pdo = pdo_kind(index)
        if pdo is None:
            return
        kind, comm, _, n = pdo
        self._plans.pop(comm, None)
        if kind == "TPDO":
            self._tpdo_last_data[n] = None
            self._sync_counts[n] = 0
        else:
            self._pending_rpdos.pop(n, None)
