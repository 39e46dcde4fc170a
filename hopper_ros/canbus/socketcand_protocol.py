"""The socketcand protocol's text (raw mode) and the hub's one address rule. No ROS.

The protocol, as python-can 4.6.1's client (can/interfaces/socketcand/socketcand.py) speaks it:
server `< hi >` on connect; client `< open CHANNEL >` -> `< ok >`; `< rawmode >` -> `< ok >`;
then frames to the client as `< frame ID SECONDS.USEC DATAHEX >` (ID: 3 hex digits for 11-bit,
8 for 29-bit identifiers; DATAHEX without spaces, empty for no data), error frames as
`< error ID SECONDS.USEC >`, and from the client `< send ID LEN B0 B1 ... >` (ID longer than 3
digits = 29-bit). The hub that speaks it: socketcand_server.py.
"""

from __future__ import annotations

import ipaddress
import re
import time

import can

_STANDARD_ID_DIGITS = 3
_MAX_STANDARD_ID = 0x7FF
_MAX_EXTENDED_ID = 0x1FFFFFFF
_MAX_CLASSIC_DLC = 8
_HEX_ID = re.compile(r"[0-9A-Fa-f]{1,8}")
_HEX_BYTE = re.compile(r"[0-9A-Fa-f]{1,2}")


def loopback_host(host: str) -> str:
    """The IPv4 loopback address to bind for `host`; ValueError for anything else."""
    name = str(host).strip()
    if name.lower() == "localhost":
        return "127.0.0.1"
    try:
        address = ipaddress.ip_address(name)
    except ValueError:
        address = None
    if address is None or address.version != 4 or not address.is_loopback:
        raise ValueError(
            f"socketcand hub: refusing to bind {host!r}: it serves loopback only (127.0.0.1); "
            "CAN frames must not leave this machine"
        )
    return str(address)


def format_frame(msg: can.Message) -> str | None:
    """A frame as socketcand sends it to clients; None for what the protocol cannot carry."""
    stamp = f"{(msg.timestamp or time.time()):.6f}"
    if msg.is_error_frame:
        return f"< error {msg.arbitration_id & _MAX_EXTENDED_ID:08X} {stamp} >"
    if msg.is_remote_frame:
        return None
    ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    return f"< frame {ident} {stamp} {bytes(msg.data).hex().upper()} >"


def parse_send(tokens: list[str]) -> can.Message:
    """`send ID LEN B0 ...` (tokens after the brackets) as a message; ValueError if malformed."""
    if len(tokens) < 3 or tokens[0] != "send":
        raise ValueError("not a send command")
    ident_text, length_text, data_text = tokens[1], tokens[2], tokens[3:]
    if not _HEX_ID.fullmatch(ident_text):
        raise ValueError(f"bad identifier {ident_text!r}")
    if not _HEX_BYTE.fullmatch(length_text) or not all(_HEX_BYTE.fullmatch(b) for b in data_text):
        raise ValueError("length and data must be hex numbers of one or two digits")
    ident = int(ident_text, 16)
    extended = len(ident_text) > _STANDARD_ID_DIGITS
    if ident > (_MAX_EXTENDED_ID if extended else _MAX_STANDARD_ID):
        raise ValueError(f"identifier {ident_text} out of range")
    length = int(length_text, 16)
    if not 0 <= length <= _MAX_CLASSIC_DLC or len(data_text) != length:
        raise ValueError(f"length {length_text} does not match {len(data_text)} data bytes")
    data = bytes(int(b, 16) for b in data_text)
    return can.Message(arbitration_id=ident, data=data, is_extended_id=extended, timestamp=time.time())
