"""A loopback-only CAN hub speaking the socketcand protocol (raw mode). No ROS.

Processes on this machine reach an in-process python-can bus through it with python-can's own
client, `can.Bus(interface="socketcand", host="127.0.0.1", port=PORT, channel="can0")`; the
in-process side (the emulated EPOS2 of the simulated robot) uses `server.local_bus()`, a
python-can `virtual` bus on the hub's channel. Every frame of one client goes to every other
client and to the in-process bus; every frame sent in-process goes to every client.

The protocol, as python-can 4.6.1's client (can/interfaces/socketcand/socketcand.py) speaks it:
server `< hi >` on connect; client `< open CHANNEL >` -> `< ok >`; `< rawmode >` -> `< ok >`;
then frames to the client as `< frame ID SECONDS.USEC DATAHEX >` (ID: 3 hex digits for 11-bit,
8 for 29-bit identifiers; DATAHEX without spaces, empty for no data), error frames as
`< error ID SECONDS.USEC >`, and from the client `< send ID LEN B0 B1 ... >` (ID longer than 3
digits = 29-bit). The client compares the handshake answers byte for byte, so no frame follows
`< ok >` for RAWMODE_GRACE; frames of that time are queued, not lost.

Robustness: the hub binds 127.0.0.1 (or another IPv4 loopback address) only and refuses any
other host; a command it cannot parse is counted (`counters.garbage_commands`) and dropped; a
client that sends an endless unterminated command or stops reading is closed; a disconnect is
just a disconnect. It runs in two daemon threads; `close()` stops them and releases everything.
"""

from __future__ import annotations

import ipaddress
import logging
import re
import selectors
import socket
import threading
import time
import uuid
from collections import deque
from dataclasses import dataclass, field

import can

log = logging.getLogger(__name__)

#: after `< ok >` to rawmode, frames wait this long [s] so the client reads the `< ok >` alone
RAWMODE_GRACE = 0.1
#: longest command accepted [characters] (`< send 1FFFFFFF 8 ff ff ... >` is about 45)
MAX_COMMAND_LENGTH = 256
#: a client that cannot take a frame within this time [s] is closed
SEND_TIMEOUT = 1.0
#: frames queued per client during RAWMODE_GRACE at most
MAX_PENDING_FRAMES = 10000
_RECV_SIZE = 4096
_SELECT_TIMEOUT = 0.01      # [s] socket thread wake-up (flushes queues after the grace time)
_BUS_TIMEOUT = 0.05         # [s] bus thread receive timeout (bounds close() latency)
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


@dataclass
class HubCounters:
    clients_accepted: int = 0
    clients_closed: int = 0
    frames_from_clients: int = 0
    frames_to_clients: int = 0
    garbage_commands: int = 0
    dropped_frames: int = 0          # frames the protocol cannot carry (RTR) or a queue overflow


@dataclass(eq=False)
class _Client:
    sock: socket.socket
    peer: tuple
    buffer: str = ""
    state: str = "greeted"           # greeted -> open -> raw
    raw_since: float = 0.0
    pending: deque = field(default_factory=lambda: deque(maxlen=MAX_PENDING_FRAMES))
    lock: threading.Lock = field(default_factory=threading.Lock)
    dead: bool = False


class SocketcandServer:
    """The hub. `start()` it, give in-process users `local_bus()`, `close()` it at the end."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, channel: str = "can0", *,
                 bus: can.BusABC | None = None, virtual_channel: str | None = None):
        """`port` 0 picks a free one (see `.port`). Without `bus` the hub makes its own virtual
        bus on `virtual_channel` (default: a unique name); with `bus`, `virtual_channel` names
        that bus's virtual channel if `local_bus()` is to be used."""
        self.host = loopback_host(host)
        self.channel = str(channel)
        self.virtual_channel = virtual_channel or f"socketcand-hub-{uuid.uuid4().hex[:12]}"
        self._own_bus = bus is None
        self._bus = bus if bus is not None else can.Bus(interface="virtual", channel=self.virtual_channel)
        self._local_buses: list[can.BusABC] = []
        self.counters = HubCounters()
        self._clients: list[_Client] = []
        self._clients_lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._closed = False
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind((self.host, int(port)))
            self._listener.listen()
            self._listener.setblocking(False)
        except OSError:
            self._listener.close()
            if self._own_bus:
                self._bus.shutdown()
            raise
        self.port = self._listener.getsockname()[1]
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)

    # ------------------------------------------------------------------ lifecycle

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    @property
    def client_count(self) -> int:
        with self._clients_lock:
            return sum(1 for c in self._clients if not c.dead)

    def start(self) -> "SocketcandServer":
        if self._threads:
            return self
        self._threads = [threading.Thread(target=self._serve_sockets, name="socketcand-sockets", daemon=True),
                         threading.Thread(target=self._serve_bus, name="socketcand-bus", daemon=True)]
        for thread in self._threads:
            thread.start()
        log.info("socketcand hub on %s:%d, channel %s", self.host, self.port, self.channel)
        return self

    def local_bus(self) -> can.BusABC:
        """A new python-can bus on the hub's in-process side (shut down by `close()`)."""
        bus = can.Bus(interface="virtual", channel=self.virtual_channel)
        self._local_buses.append(bus)
        return bus

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._wake()
        for thread in self._threads:
            thread.join(5.0)
        with self._clients_lock:
            clients, self._clients = self._clients, []
        for client in clients:
            self._close_socket(client.sock)
        self._listener.close()
        self._wake_r.close()
        self._wake_w.close()
        for bus in self._local_buses:
            bus.shutdown()
        if self._own_bus:
            self._bus.shutdown()

    def __enter__(self) -> "SocketcandServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ socket side

    def _wake(self) -> None:
        try:
            self._wake_w.send(b"\0")
        except OSError:
            pass

    def _serve_sockets(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._listener, selectors.EVENT_READ, "listen")
        selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        registered: set[_Client] = set()
        try:
            while not self._stop.is_set():
                for key, _ in selector.select(_SELECT_TIMEOUT):
                    if key.data == "listen":
                        self._accept(selector, registered)
                    elif key.data == "wake":
                        try:
                            self._wake_r.recv(_RECV_SIZE)
                        except OSError:
                            pass
                    else:
                        self._read(key.data)
                self._flush_pending()
                for client in [c for c in registered if c.dead]:
                    selector.unregister(client.sock)
                    registered.discard(client)
                    self._drop(client)
        except Exception:                                     # keep close() working
            log.exception("socketcand hub: socket thread failed")
        finally:
            selector.close()

    def _accept(self, selector, registered: set) -> None:
        try:
            sock, peer = self._listener.accept()
        except OSError:
            return
        sock.setblocking(True)
        sock.settimeout(SEND_TIMEOUT)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock=sock, peer=peer)
        self.counters.clients_accepted += 1
        if not self._send_text(client, "< hi >"):
            self._drop(client)
            return
        with self._clients_lock:
            self._clients.append(client)
        selector.register(sock, selectors.EVENT_READ, client)
        registered.add(client)
        log.info("socketcand hub: client %s connected", peer)

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(_RECV_SIZE)
        except (OSError, socket.timeout):
            data = b""
        if not data:
            client.dead = True                               # disconnected
            return
        client.buffer += data.decode("ascii", errors="replace")
        self._parse(client)

    def _parse(self, client: _Client) -> None:
        buf = client.buffer
        while buf:
            start = buf.find("<")
            if start < 0:
                if buf.strip():
                    self.counters.garbage_commands += 1
                buf = ""
                break
            if buf[:start].strip():
                self.counters.garbage_commands += 1          # junk between commands
            end = buf.find(">", start)
            if end < 0:
                buf = buf[start:]
                if len(buf) > MAX_COMMAND_LENGTH:
                    self.counters.garbage_commands += 1
                    log.warning("socketcand hub: client %s sent an endless command; closing it", client.peer)
                    client.dead = True
                    buf = ""
                break
            inner = buf[start + 1:end]
            buf = buf[end + 1:]
            if "<" in inner:                                  # an unterminated command before
                self.counters.garbage_commands += 1
                inner = inner[inner.rfind("<") + 1:]
            self._command(client, inner.split())
        client.buffer = buf

    def _command(self, client: _Client, tokens: list[str]) -> None:
        verb = tokens[0] if tokens else ""
        if verb == "open" and len(tokens) == 2 and client.state == "greeted":
            if tokens[1] == self.channel:
                client.state = "open"
                self._send_text(client, "< ok >")
            else:
                self._send_text(client, "< error could not open bus >")
        elif verb == "rawmode" and len(tokens) == 1 and client.state in ("open", "raw"):
            with client.lock:
                client.raw_since = time.monotonic()
                client.state = "raw"
                self._sendall_locked(client, "< ok >")
        elif verb == "echo" and len(tokens) == 1:
            self._send_text(client, "< echo >")
        elif verb == "send" and client.state in ("open", "raw"):
            try:
                msg = parse_send(tokens)
            except ValueError as exc:
                self.counters.garbage_commands += 1
                log.debug("socketcand hub: dropped %r: %s", " ".join(tokens), exc)
                return
            self.counters.frames_from_clients += 1
            msg.channel = self.channel
            try:
                self._bus.send(msg)
            except can.CanError as exc:
                log.warning("socketcand hub: in-process send failed: %s", exc)
            self._broadcast(msg, exclude=client)
        else:
            self.counters.garbage_commands += 1
            log.debug("socketcand hub: dropped unknown command %r", " ".join(tokens))

    # ------------------------------------------------------------------ frames to clients

    def _serve_bus(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self._bus.recv(timeout=_BUS_TIMEOUT)
            except Exception as exc:                         # the bus went away: stop quietly
                if not self._stop.is_set():
                    log.warning("socketcand hub: bus receive failed: %s", exc)
                    time.sleep(_BUS_TIMEOUT)
                continue
            if msg is not None:
                self._broadcast(msg)

    def _broadcast(self, msg: can.Message, exclude: _Client | None = None) -> None:
        text = format_frame(msg)
        if text is None:
            self.counters.dropped_frames += 1
            return
        with self._clients_lock:
            clients = [c for c in self._clients if c is not exclude and not c.dead and c.state == "raw"]
        for client in clients:
            self._deliver(client, text)

    def _flush_pending(self) -> None:
        with self._clients_lock:
            clients = [c for c in self._clients if c.pending and not c.dead]
        for client in clients:
            self._deliver(client, None)

    def _deliver(self, client: _Client, text: str | None) -> None:
        """Queue during the rawmode grace time, else send the queue and `text` (in order)."""
        with client.lock:
            if time.monotonic() - client.raw_since < RAWMODE_GRACE:
                if text is not None:
                    if len(client.pending) == client.pending.maxlen:
                        self.counters.dropped_frames += 1
                    client.pending.append(text)
                return
            texts = list(client.pending) + ([text] if text is not None else [])
            client.pending.clear()
            if texts and self._sendall_locked(client, "".join(texts)):
                self.counters.frames_to_clients += len(texts)

    def _send_text(self, client: _Client, text: str) -> bool:
        with client.lock:
            return self._sendall_locked(client, text)

    def _sendall_locked(self, client: _Client, text: str) -> bool:
        try:
            client.sock.sendall(text.encode("ascii"))
            return True
        except (OSError, socket.timeout) as exc:
            if not client.dead:
                log.info("socketcand hub: client %s gone (%s)", client.peer, exc)
            client.dead = True
            self._wake()
            return False

    def _drop(self, client: _Client) -> None:
        client.dead = True
        with self._clients_lock:
            if client in self._clients:
                self._clients.remove(client)
        self._close_socket(client.sock)
        self.counters.clients_closed += 1
        log.info("socketcand hub: client %s closed", client.peer)

    @staticmethod
    def _close_socket(sock: socket.socket) -> None:
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        sock.close()
