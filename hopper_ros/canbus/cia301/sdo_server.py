"""A device's SDO server (CiA 301): expedited and segmented upload and download, one transfer at a
time, and a CiA 301 abort for anything it cannot do (block transfers included). The device's object
dictionary decides what may be read and written (`SdoDictionary`); what it refuses is `SdoRefused`
with the abort code, answered as an SDO abort. The client side is `master.SdoClient`, whose
`SdoError` is the abort it receives.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Callable, Protocol

from hopper_ros.canbus import epos2_objects as od
from hopper_ros.canbus.epos2_objects import SdoAbort

from .counters import Counters

MAX_SEGMENTED_SIZE = 1024          # [bytes] largest segmented download accepted


class SdoRefused(Exception):
    """An SDO request the dictionary refuses, with its CiA 301 abort code."""

    def __init__(self, code: int):
        super().__init__(od.sdo_abort_text(code))
        self.code = int(code)


class SdoDictionary(Protocol):
    """The device's object dictionary as the SDO server sees it; each raises SdoRefused."""

    def read(self, index: int, sub: int) -> bytes: ...

    def write(self, index: int, sub: int, payload: bytes) -> None: ...

    def check_writable(self, index: int, sub: int) -> object: ...

    def size_of(self, index: int, sub: int) -> int | None: ...


@dataclass
class SegmentedTransfer:
    """State of a segmented SDO transfer in progress."""

    upload: bool
    index: int
    subindex: int
    data: bytearray = field(default_factory=bytearray)
    size: int | None = None
    toggle: int = 0
    offset: int = 0


class SdoServer:
    """The SDO server of node `node_id`: `on_frame(data)` for every frame on its receive COB-ID; the
    answers go out through `send(cob_id, data)`."""

    def __init__(self, node_id: int, dictionary: SdoDictionary, send: Callable[[int, bytes], None],
                 counters: Counters, max_segmented_size: int = MAX_SEGMENTED_SIZE) -> None:
        self.node_id = node_id
        self.dictionary = dictionary
        self._send = send
        self.counters = counters
        self.max_segmented_size = max_segmented_size
        self.transfer: SegmentedTransfer | None = None

    def reset(self) -> None:
        """Communication reset: a transfer in progress is forgotten."""
        self.transfer = None

    def on_frame(self, data: bytes) -> None:
        if len(data) != od.SDO_FRAME_LENGTH:
            self.counters.malformed_frames += 1
            padded = data.ljust(4, b"\0")
            index, sub = struct.unpack_from("<HB", padded, 1)
            self._abort(index, sub, SdoAbort.UNKNOWN_COMMAND)
            return
        ccs = data[0] >> 5
        index, sub = struct.unpack_from("<HB", data, 1)
        try:
            if ccs == od.SDO_CS_ABORT:
                self.transfer = None             # the client aborted: no answer
            elif ccs == od.SDO_CCS_INITIATE_UPLOAD:
                self.transfer = None
                self._initiate_upload(index, sub)
            elif ccs == od.SDO_CCS_INITIATE_DOWNLOAD:
                self.transfer = None
                self._initiate_download(data, index, sub)
            elif ccs == od.SDO_CCS_UPLOAD_SEGMENT:
                self._upload_segment(data)
            elif ccs == od.SDO_CCS_DOWNLOAD_SEGMENT:
                self._download_segment(data)
            else:                                # block transfers and reserved specifiers
                raise SdoRefused(SdoAbort.UNKNOWN_COMMAND)
        except SdoRefused as exc:
            if self.transfer is not None:
                index, sub = self.transfer.index, self.transfer.subindex
            self.transfer = None
            self._abort(index, sub, exc.code)

    def _reply(self, data: bytes) -> None:
        self._send(od.sdo_tx_cob_id(self.node_id), data.ljust(od.SDO_FRAME_LENGTH, b"\0"))

    def _abort(self, index: int, sub: int, code: int) -> None:
        self.counters.sdo_aborts += 1
        self._reply(struct.pack("<BHBI", od.SDO_ABORT_BYTE, index, sub, int(code)))

    def _initiate_upload(self, index: int, sub: int) -> None:
        raw = self.dictionary.read(index, sub)
        if len(raw) <= 4:
            cmd = (od.SDO_SCS_INITIATE_UPLOAD << 5) | ((4 - len(raw)) << 2) | od.SDO_EXPEDITED_BIT | od.SDO_SIZE_BIT
            self._reply(struct.pack("<BHB", cmd, index, sub) + raw)
        else:
            self.transfer = SegmentedTransfer(upload=True, index=index, subindex=sub, data=bytearray(raw))
            cmd = (od.SDO_SCS_INITIATE_UPLOAD << 5) | od.SDO_SIZE_BIT
            self._reply(struct.pack("<BHBI", cmd, index, sub, len(raw)))

    def _upload_segment(self, data: bytes) -> None:
        t = self.transfer
        if t is None or not t.upload:
            raise SdoRefused(SdoAbort.UNKNOWN_COMMAND)
        toggle = (data[0] >> 4) & 1
        if toggle != t.toggle:
            raise SdoRefused(SdoAbort.TOGGLE_BIT_NOT_ALTERNATED)
        chunk = bytes(t.data[t.offset:t.offset + 7])
        t.offset += len(chunk)
        last = t.offset >= len(t.data)
        cmd = (od.SDO_SCS_UPLOAD_SEGMENT << 5) | (toggle << 4) | ((7 - len(chunk)) << 1) | (1 if last else 0)
        self._reply(bytes([cmd]) + chunk)
        t.toggle ^= 1
        if last:
            self.transfer = None

    def _initiate_download(self, data: bytes, index: int, sub: int) -> None:
        cmd = data[0]
        if cmd & od.SDO_EXPEDITED_BIT:
            if cmd & od.SDO_SIZE_BIT:
                payload = data[4:8 - ((cmd >> 2) & 0x3)]
            else:
                payload = data[4:8]              # size not indicated: the object's own size
                size = self.dictionary.size_of(index, sub)
                payload = payload[:size] if size is not None else payload.rstrip(b"\0")
            self.dictionary.write(index, sub, payload)
            self._reply(struct.pack("<BHB", od.SDO_SCS_INITIATE_DOWNLOAD << 5, index, sub))
            return
        self.dictionary.check_writable(index, sub)
        size = struct.unpack_from("<I", data, 4)[0] if cmd & od.SDO_SIZE_BIT else None
        if size is not None and size > self.max_segmented_size:
            raise SdoRefused(SdoAbort.OUT_OF_MEMORY)
        self.transfer = SegmentedTransfer(upload=False, index=index, subindex=sub, size=size)
        self._reply(struct.pack("<BHB", od.SDO_SCS_INITIATE_DOWNLOAD << 5, index, sub))

    def _download_segment(self, data: bytes) -> None:
        t = self.transfer
        if t is None or t.upload:
            raise SdoRefused(SdoAbort.UNKNOWN_COMMAND)
        toggle = (data[0] >> 4) & 1
        if toggle != t.toggle:
            raise SdoRefused(SdoAbort.TOGGLE_BIT_NOT_ALTERNATED)
        unused = (data[0] >> 1) & 0x7
        t.data += data[1:8 - unused]
        if len(t.data) > self.max_segmented_size:
            raise SdoRefused(SdoAbort.OUT_OF_MEMORY)
        last = bool(data[0] & od.SDO_SEGMENT_LAST_BIT)
        if last:
            if t.size is not None and t.size != len(t.data):
                raise SdoRefused(SdoAbort.LENGTH_MISMATCH)
            self.dictionary.write(t.index, t.subindex, bytes(t.data))
        self._reply(bytes([(od.SDO_SCS_DOWNLOAD_SEGMENT << 5) | (toggle << 4)]))
        t.toggle ^= 1
        if last:
            self.transfer = None
