"""CANopen master primitives for one node (CiA 301), our own code on python-can frames. No ROS.

- NMT: `nmt_frame` (start, stop, pre-operational, resets) and `NmtState` of heartbeats;
- SDO: `SdoClient`, an expedited client, one transfer at a time, non-blocking (the caller feeds
  it the server's answers and the time), with timeouts and abort decoding (`SdoError`);
- PDO: `PdoMapping`, a PDO's layout from its mapping entries, to encode and decode payloads
  and to write it into the 0x16xx / 0x1Axx mapping objects;
- SYNC: `sync_frame`; heartbeat: `heartbeat_frame` (producer), `HeartbeatConsumer`;
- EMCY: `decode_emcy` into EPOS2 error texts.

Time is whatever the caller's clock says (seconds); nothing here sleeps or reads the bus. The
`canopen` library is not used: it is the independent peer of the tests.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import can

from hopper_ros.canbus.epos2_objects import (
    NMT_COB_ID,
    SDO_ABORT_BYTE,
    SDO_EXPEDITED_BIT,
    SDO_SIZE_BIT,
    SYNC_COB_ID,
    NmtCommand,
    NmtState,
    SdoAbort,
    error_text,
    heartbeat_cob_id,
    pdo_mapping_entry,
    sdo_abort_text,
    sdo_rx_cob_id,
    sdo_tx_cob_id,
)

__all__ = [
    "NmtCommand", "NmtState", "nmt_frame", "sync_frame", "heartbeat_frame", "nmt_state_name",
    "SdoError", "SdoTransfer", "SdoClient", "PdoEntry", "PdoMapping", "HeartbeatConsumer",
    "Emergency", "decode_emcy", "MalformedFrame",
]


class MalformedFrame(ValueError):
    """A frame on one of our COB-IDs that does not follow the protocol.

    `transfer`: the SDO transfer the frame made fail (aborted), if any.
    """

    def __init__(self, text: str, transfer: "SdoTransfer | None" = None):
        super().__init__(text)
        self.transfer = transfer


def _frame(cob_id: int, data: bytes | Sequence[int]) -> can.Message:
    return can.Message(arbitration_id=cob_id, data=bytes(data), is_extended_id=False)


# ------------------------------------------------------------------------------------- NMT, SYNC


def nmt_frame(command: NmtCommand, node_id: int) -> can.Message:
    """NMT node control: [command, node id] on COB-ID 0 (node id 0 addresses every node)."""
    return _frame(NMT_COB_ID, (int(command), int(node_id)))


def sync_frame() -> can.Message:
    """SYNC without counter (0x1019 = 0): an empty frame on 0x080."""
    return _frame(SYNC_COB_ID, b"")


def heartbeat_frame(node_id: int, state: NmtState = NmtState.OPERATIONAL) -> can.Message:
    """Heartbeat of a producer (the master's own, for the drive's heartbeat consumer)."""
    return _frame(heartbeat_cob_id(node_id), (int(state),))


def nmt_state_name(state: int | None) -> str:
    if state is None:
        return "UNKNOWN"
    try:
        return NmtState(state).name
    except ValueError:
        return f"0x{state:02X}"


# ------------------------------------------------------------------------------------------- SDO


class SdoError(Exception):
    """An SDO transfer that failed: aborted by the server (or us), timed out, or malformed."""

    def __init__(self, index: int, subindex: int, code: int, text: str | None = None):
        self.index, self.subindex, self.code = index, subindex, int(code)
        self.text = text if text is not None else sdo_abort_text(code)
        super().__init__(f"SDO 0x{index:04X}:{subindex:02X}: 0x{self.code:08X} {self.text}")

    @property
    def timed_out(self) -> bool:
        return self.code == SdoAbort.TIMEOUT


@dataclass
class SdoTransfer:
    """One expedited transfer; `done` once answered, aborted or timed out."""

    index: int
    subindex: int
    upload: bool
    data: bytes | None          # download: the value written; upload: the value read
    started: float
    done: bool = False
    error: SdoError | None = None
    tag: object = None          # the caller's, e.g. what to do with the answer

    @property
    def ok(self) -> bool:
        return self.done and self.error is None

    def value(self, fmt: str) -> int:
        """The uploaded value as a struct format (e.g. "<H"), checking the size."""
        if self.data is None or len(self.data) < struct.calcsize(fmt):
            raise SdoError(self.index, self.subindex, SdoAbort.LENGTH_TOO_LOW)
        return struct.unpack_from(fmt, self.data)[0]


class SdoClient:
    """Expedited SDO client of one server (node id): at most one transfer in flight.

    `download` / `upload` send the initiate request; `on_frame` takes the server's answer
    (COB-ID 0x580 + id) and returns the transfer it finished; `poll(now)` ends a transfer that
    timed out (sending an abort, CiA 301's "SDO protocol timed out"). Values longer than 4 bytes
    (segmented transfers) are refused: the drive's configuration needs none.
    """

    def __init__(self, node_id: int, send: Callable[[can.Message], None], timeout: float):
        self.node_id = node_id
        self.rx_cob_id = sdo_tx_cob_id(node_id)       # answers arrive here
        self.tx_cob_id = sdo_rx_cob_id(node_id)       # requests go here
        self._send = send
        self.timeout = float(timeout)
        self.current: SdoTransfer | None = None

    @property
    def busy(self) -> bool:
        return self.current is not None

    def download(self, index: int, subindex: int, data: bytes, now: float, tag: object = None) -> SdoTransfer:
        """Write 1..4 bytes (expedited initiate download, size indicated)."""
        if not 1 <= len(data) <= 4:
            raise ValueError(f"expedited SDO download takes 1..4 bytes, got {len(data)}")
        command = 0x20 | ((4 - len(data)) << 2) | SDO_EXPEDITED_BIT | SDO_SIZE_BIT
        return self._start(SdoTransfer(index, subindex, False, bytes(data), now, tag=tag), command, data)

    def upload(self, index: int, subindex: int, now: float, tag: object = None) -> SdoTransfer:
        """Read a value of at most 4 bytes (expedited initiate upload)."""
        return self._start(SdoTransfer(index, subindex, True, None, now, tag=tag), 0x40, b"")

    def _start(self, transfer: SdoTransfer, command: int, payload: bytes) -> SdoTransfer:
        if self.current is not None:
            raise RuntimeError(f"SDO client busy with 0x{self.current.index:04X}:{self.current.subindex:02X}")
        self.current = transfer
        frame = struct.pack("<BHB", command, transfer.index, transfer.subindex) + payload.ljust(4, b"\0")
        self._send(_frame(self.tx_cob_id, frame))
        return transfer

    def abort(self, code: int = SdoAbort.GENERAL_ERROR) -> SdoTransfer | None:
        """Abort the transfer in flight (tells the server); returns it, failed."""
        transfer = self.current
        if transfer is None:
            return None
        self._send(_frame(self.tx_cob_id, struct.pack("<BHBI", SDO_ABORT_BYTE, transfer.index, transfer.subindex, code)))
        return self._finish(SdoError(transfer.index, transfer.subindex, code))

    def poll(self, now: float) -> SdoTransfer | None:
        """The transfer that timed out at `now` (aborted), else None."""
        if self.current is not None and now - self.current.started > self.timeout:
            return self.abort(SdoAbort.TIMEOUT)
        return None

    def on_frame(self, data: bytes) -> SdoTransfer | None:
        """Take a server answer; the finished transfer, or None if it is not for the one in flight.

        Raises MalformedFrame for a frame of the wrong length, or an answer to our transfer that
        breaks the protocol (the transfer then fails, aborted towards the server).
        """
        if len(data) != 8:
            raise MalformedFrame(f"SDO answer of {len(data)} bytes (8 expected)")
        command = data[0]
        index, subindex = struct.unpack_from("<HB", data, 1)
        transfer = self.current
        if transfer is None or (index, subindex) != (transfer.index, transfer.subindex):
            return None  # not (or no longer) ours: another client's answer, or one after our timeout
        if command == SDO_ABORT_BYTE:
            return self._finish(SdoError(index, subindex, struct.unpack_from("<I", data, 4)[0]))
        scs = command >> 5
        if not transfer.upload and scs == 3:                       # initiate download response
            return self._finish(None)
        if transfer.upload and scs == 2:                           # initiate upload response
            if not command & SDO_EXPEDITED_BIT:
                self.abort(SdoAbort.UNKNOWN_COMMAND)               # segmented: not supported here
                transfer.error = SdoError(index, subindex, SdoAbort.LENGTH_TOO_HIGH,
                                          "value longer than 4 bytes (segmented upload not supported)")
                return transfer
            size = 4 - ((command >> 2) & 0x3) if command & SDO_SIZE_BIT else 4
            transfer.data = bytes(data[4:4 + size])
            return self._finish(None)
        failed = self.abort(SdoAbort.UNKNOWN_COMMAND)
        raise MalformedFrame(f"SDO answer 0x{command:02X} does not fit the {'upload' if transfer.upload else 'download'} "
                             f"of 0x{index:04X}:{subindex:02X}", failed)

    def _finish(self, error: SdoError | None) -> SdoTransfer:
        transfer = self.current
        self.current = None
        transfer.done, transfer.error = True, error
        return transfer


# ------------------------------------------------------------------------------------------- PDO


_INT_FORMATS = {(8, False): "B", (8, True): "b", (16, False): "H", (16, True): "h",
                (32, False): "I", (32, True): "i"}


@dataclass(frozen=True)
class PdoEntry:
    """One mapped object: index, subindex, size in bits (8, 16, 32) and signedness."""

    index: int
    subindex: int
    bits: int
    signed: bool
    name: str = ""

    @property
    def mapping(self) -> int:
        return pdo_mapping_entry(self.index, self.subindex, self.bits)


@dataclass(frozen=True)
class PdoMapping:
    """The layout of one PDO: its entries packed little-endian in order (CiA 301)."""

    entries: tuple[PdoEntry, ...]
    _format: str = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        try:
            fmt = "<" + "".join(_INT_FORMATS[(entry.bits, entry.signed)] for entry in self.entries)
        except KeyError as exc:
            raise ValueError(f"unsupported PDO entry size {exc.args[0]}") from None
        if struct.calcsize(fmt) > 8:
            raise ValueError(f"PDO mapping of {struct.calcsize(fmt)} bytes exceeds 8")
        object.__setattr__(self, "_format", fmt)

    @classmethod
    def of(cls, entries: Iterable[PdoEntry]) -> "PdoMapping":
        return cls(tuple(entries))

    @property
    def size(self) -> int:
        """Payload length in bytes."""
        return struct.calcsize(self._format)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(entry.name for entry in self.entries)

    def encode(self, values: Sequence[int]) -> bytes:
        """Payload of integer values in mapping order (each must fit its entry)."""
        try:
            return struct.pack(self._format, *(int(v) for v in values))
        except struct.error as exc:
            raise ValueError(f"PDO values {tuple(values)} do not fit {self.names}: {exc}") from None

    def decode(self, data: bytes) -> tuple[int, ...]:
        """Values of a payload; MalformedFrame if its length is not the mapping's."""
        if len(data) != self.size:
            raise MalformedFrame(f"PDO of {len(data)} bytes, mapping {self.names} needs {self.size}")
        return struct.unpack(self._format, bytes(data))


# ------------------------------------------------------------------------------------- heartbeat


class HeartbeatConsumer:
    """Watches one producer's heartbeat (COB-ID 0x700 + id): its NMT state and whether it is alive.

    Alive once a heartbeat came and then as long as the next comes within `timeout`. `check(now)`
    returns True once per loss (the transition alive -> lost); `arm(now)` starts the timeout
    without a heartbeat yet (after configuring the producer), so silence also counts as loss.
    """

    def __init__(self, node_id: int, timeout: float):
        self.cob_id = heartbeat_cob_id(node_id)
        self.timeout = float(timeout)
        self.state: int | None = None
        self.last_seen: float | None = None
        self.armed_at: float | None = None
        self.alive = False
        self.bootups = 0

    def arm(self, now: float) -> None:
        if self.last_seen is None and self.armed_at is None:
            self.armed_at = now
            self.alive = True  # give the producer its first timeout

    def on_frame(self, data: bytes, now: float) -> int:
        """Take a heartbeat; its NMT state. MalformedFrame if it is not one."""
        if len(data) != 1:
            raise MalformedFrame(f"heartbeat of {len(data)} bytes (1 expected)")
        state = data[0] & 0x7F  # bit 7 is the node guarding toggle bit
        if state not in NmtState._value2member_map_:
            raise MalformedFrame(f"heartbeat with unknown NMT state 0x{state:02X}")
        if state == NmtState.BOOTUP:
            self.bootups += 1
        self.state, self.last_seen, self.alive = state, now, True
        return state

    def check(self, now: float) -> bool:
        """True when the heartbeat has just been lost (once per loss)."""
        reference = self.last_seen if self.last_seen is not None else self.armed_at
        if self.alive and reference is not None and now - reference > self.timeout:
            self.alive = False
            return True
        return False


# ------------------------------------------------------------------------------------------ EMCY


@dataclass(frozen=True)
class Emergency:
    """An EMCY message: error code, error register, manufacturer bytes, and the code's text."""

    code: int
    register: int
    manufacturer: bytes
    text: str

    @property
    def is_reset(self) -> bool:
        """Code 0: "error reset or no error" (sent when a fault is reset)."""
        return self.code == 0


def decode_emcy(data: bytes, describe: Callable[[int], str] = error_text) -> Emergency:
    """Decode an EMCY payload (8 bytes: code u16, register u8, 5 manufacturer bytes)."""
    if len(data) != 8:
        raise MalformedFrame(f"EMCY of {len(data)} bytes (8 expected)")
    code, register = struct.unpack_from("<HB", data)
    return Emergency(code, register, bytes(data[3:8]), describe(code))
