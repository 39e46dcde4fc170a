"""A loopback-only CAN hub speaking the socketcand protocol (raw mode). No ROS.

Processes on this machine reach an in-process python-can bus through it with python-can's own
client, `can.Bus(interface="socketcand", host="127.0.0.1", port=PORT, channel="can0")`; the
in-process side (the emulated EPOS2 of the simulated robot) uses `server.local_bus()`, a
python-can bus of the hub's own (`LocalBus`). Every frame of one client goes to every other
client and to every local bus; every frame sent on a local bus goes to every client and every
other local bus. A local bus hands frames over directly, without a thread of its own or python-can's
`virtual` bus (a deep copy per frame and receiver, a queue, a thread waking per frame: 0.1-0.15 core of
the simulated robot's real-time process at 1 kHz, issue 29).

The protocol (socketcand_protocol.py), as python-can 4.6.1's client speaks it: a handshake
(`< hi >`, `< open CHANNEL >`, `< rawmode >`, each answered `< ok >`), then frames both ways. The
client compares the handshake answers byte for byte, so no frame follows `< ok >` for
RAWMODE_GRACE; frames of that time are queued, not lost.

Nothing a client does can stall the hub (issue 17). Every client socket is non-blocking and
only the socket thread writes to it. Frames to clients go into one shared, bounded log of
formatted frames (`MAX_QUEUED_FRAMES`); each client has a cursor into it and an output buffer
of at most `MAX_OUTPUT_BYTES`. Each turn of the socket thread moves every client's new frames
into its buffer and sends what the kernel takes; a client whose socket is full is left until
the selector says it is writable again. A client that falls a whole log behind (it stopped
reading, or reads slower than the bus) is closed and counted (`slow_clients_dropped`); the other
clients never wait for it. The in-process side never waits either: a local bus's send only appends
to the log, and its wake-up of the socket thread is a non-blocking write that is skipped while
one is pending. A turn of the socket thread is bounded by the number of clients, so the more
clients there are, the more frames each `send` carries.

Robustness otherwise: the hub binds 127.0.0.1 (or another IPv4 loopback address) only and
refuses any other host; a command it cannot parse is counted (`garbage_commands`) and dropped;
a client that sends an endless unterminated command, does not finish the handshake within
`HANDSHAKE_TIMEOUT` or would exceed `MAX_CLIENTS` is closed (counted); a disconnect is just a
disconnect. It runs in a daemon thread; `close()` stops it within about 0.1 s and releases
everything.
"""

from __future__ import annotations

import copy
import errno
import logging
import re
import selectors
import socket
import struct
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from itertools import islice

import can

from .socketcand_protocol import format_frame, loopback_host, parse_send

log = logging.getLogger(__name__)

#: after `< ok >` to rawmode, frames wait this long [s] so the client reads the `< ok >` alone
RAWMODE_GRACE = 0.1
#: longest command accepted [characters] (`< send 1FFFFFFF 8 ff ff ... >` is about 45)
MAX_COMMAND_LENGTH = 256
#: frames kept for clients that have not taken them yet; a client further behind is dropped
#: (at the drive's ~3000 frames/s of a 1 kHz SYNC loop: about 1.3 s)
MAX_QUEUED_FRAMES = 4096
#: bytes waiting in one client's output buffer at most (frames stay in the log beyond it)
MAX_OUTPUT_BYTES = 64 * 1024
#: kernel send buffer per client [bytes]: a client that stops reading is noticed quickly
CLIENT_SEND_BUFFER = 64 * 1024
#: a client must reach raw mode within this time [s] (frees slots held by idle connections)
HANDSHAKE_TIMEOUT = 5.0
#: clients served at once; more are accepted and closed at once (counted)
MAX_CLIENTS = 512
#: replies (`< ok >`, `< echo >`, ...) waiting for one client at most [bytes]
MAX_REPLY_BYTES = 4096
_RECV_SIZE = 4096
_SELECT_TIMEOUT = 0.01      # [s] socket thread wake-up (flushes queues after the grace time)
_ACCEPTS_PER_TURN = 64      # connections accepted per socket-thread turn at most
_READS_PER_TURN = 16        # reads per client per turn at most (one client cannot starve the rest)


@dataclass
class HubCounters:
    clients_accepted: int = 0
    clients_closed: int = 0
    frames_from_clients: int = 0
    frames_to_clients: int = 0       # frames handed to client sockets (summed over clients)
    garbage_commands: int = 0
    dropped_frames: int = 0          # frames the protocol cannot carry (RTR)
    slow_clients_dropped: int = 0    # closed: fell MAX_QUEUED_FRAMES behind or let replies pile up
    clients_refused: int = 0         # closed at accept: MAX_CLIENTS reached or no descriptor left
    handshake_timeouts: int = 0      # closed: not in raw mode within HANDSHAKE_TIMEOUT
    local_frames_dropped: int = 0    # the oldest frames of a local bus whose receiver left MAX_QUEUED_FRAMES unread


@dataclass(eq=False)
class _Client:
    sock: socket.socket
    peer: tuple
    accepted: float
    buffer: str = ""
    state: str = "greeted"           # greeted -> open -> raw
    raw_since: float = 0.0
    cursor: int = 0                  # sequence number of the next log entry this client needs
    output: bytearray = field(default_factory=bytearray)   # frames taken from the log, unsent
    replies: bytearray = field(default_factory=bytearray)  # handshake/echo answers, sent first
    writable: bool = True            # False after EAGAIN until the selector reports EVENT_WRITE
    watch_write: bool = False        # registered for EVENT_WRITE
    dead: bool = False
    slow: bool = False               # dropped for not keeping up (closed with a reset)
    reason: str = ""


class _FrameLog:
    """Formatted frames for the clients, numbered; the oldest go when MAX_QUEUED_FRAMES are kept."""

    def __init__(self, capacity: int):
        self.lock = threading.Lock()
        self.entries: deque = deque()        # (origin client or None, ascii bytes)
        self.first = 0                       # sequence number of entries[0]
        self.capacity = capacity

    @property
    def head(self) -> int:
        return self.first + len(self.entries)

    def since(self, cursor: int) -> tuple[int, list]:
        """(sequence number of the first entry returned, the entries from `cursor` on, or from the oldest kept);
        a copy of the new entries only (a copy of the whole log every turn of the socket thread cost the simulated
        robot's process CPU that its real-time loop needs: issue 29)."""
        with self.lock:
            start = max(cursor, self.first)
            count = self.first + len(self.entries) - start
            return start, list(islice(reversed(self.entries), max(count, 0)))[::-1]

    def append(self, origin, data: bytes) -> None:
        with self.lock:
            self.entries.append((origin, data))
            if len(self.entries) > self.capacity:
                self.entries.popleft()
                self.first += 1


class SocketcandServer:
    """The hub. `start()` it, give in-process users `local_bus()`, `close()` it at the end."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, channel: str = "can0"):
        """`port` 0 picks a free one (see `.port`)."""
        self.host = loopback_host(host)
        self.channel = str(channel)
        self._local_buses: tuple[LocalBus, ...] = ()     # copy on write: senders read it without a lock
        self._local_lock = threading.Lock()
        self.counters = HubCounters()
        self._log = _FrameLog(MAX_QUEUED_FRAMES)
        self._clients: list[_Client] = []        # the socket thread's; others read a snapshot
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._closed = False
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind((self.host, int(port)))
            self._listener.listen(128)
            self._listener.setblocking(False)
        except OSError:
            self._listener.close()
            raise
        self.port = self._listener.getsockname()[1]
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)          # a full pipe means a wake-up is pending anyway
        self._wake_pending = threading.Event()
        self._turn = threading.Lock()             # one turn of the socket thread, or read_pending

    # ------------------------------------------------------------------ lifecycle

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    @property
    def client_count(self) -> int:
        return sum(1 for c in list(self._clients) if not c.dead)

    def start(self) -> "SocketcandServer":
        if self._threads:
            return self
        self._threads = [threading.Thread(target=self._serve_sockets, name="socketcand-sockets", daemon=True)]
        for thread in self._threads:
            thread.start()
        log.info("socketcand hub on %s:%d, channel %s", self.host, self.port, self.channel)
        return self

    def local_bus(self) -> "LocalBus":
        """A new python-can bus on the hub's in-process side (shut down by `close()`)."""
        bus = LocalBus(self)
        with self._local_lock:
            self._local_buses = self._local_buses + (bus,)
        return bus

    def _from_local(self, msg: can.Message, origin: "LocalBus") -> None:
        """A frame sent on a local bus: to the other local buses, and to the clients on the socket thread's next
        turn (woken now)."""
        others = [bus for bus in self._local_buses if bus is not origin]
        if others:                                # a copy of the sender's frame, received now
            frame = copy.copy(msg)
            frame.timestamp, frame.channel, frame.is_rx = time.time(), self.channel, True
            for bus in others:
                bus.deliver(frame)
        self._publish(msg, origin=None)
        self._wake()

    def close(self) -> None:
        """Stop the socket thread (it wakes at least every 10 ms) and close every socket and local bus."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._wake()
        for thread in self._threads:
            thread.join(2.0)
        for client in list(self._clients):
            self._close_socket(client.sock)
        self._clients = []
        self._listener.close()
        self._wake_r.close()
        self._wake_w.close()
        for bus in self._local_buses:
            bus.shutdown()

    def __enter__(self) -> "SocketcandServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ socket thread

    def _wake(self) -> None:
        """Wake the socket thread; never blocks (one pending wake-up is enough)."""
        if self._wake_pending.is_set():
            return
        self._wake_pending.set()
        try:
            self._wake_w.send(b"\0")
        except OSError:                       # full (a wake-up is pending) or closed
            pass

    def _serve_sockets(self) -> None:
        selector = selectors.DefaultSelector()
        selector.register(self._listener, selectors.EVENT_READ, "listen")
        selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        try:
            while not self._stop.is_set():
                ready = selector.select(_SELECT_TIMEOUT)
                with self._turn:
                    self._serve(selector, ready)
        except Exception:                                     # keep close() working
            log.exception("socketcand hub: socket thread failed")
        finally:
            selector.close()

    def _serve(self, selector, ready) -> None:
        for key, events in ready:
            if key.data == "listen":
                self._accept(selector)
            elif key.data == "wake":
                self._wake_pending.clear()
                try:
                    while self._wake_r.recv(_RECV_SIZE):
                        pass
                except OSError:
                    pass
            else:
                client = key.data
                if events & selectors.EVENT_WRITE:
                    client.writable = True
                if events & selectors.EVENT_READ:
                    self._read(client)
        self._flush(selector)

    def read_pending(self) -> None:
        """Take in now every frame that has reached a client's socket (any thread; the socket thread's work,
        done at once): the simulated robot, woken from a stop, has its drive see them as sent while it stood
        still (Epos2Emulator.discard_syncs), whichever of its threads ran first. A frame its sender still holds
        (python-can's client leaves Nagle on: a small frame waits for the last one's acknowledgement) comes
        later and counts as sent after the wake-up."""
        with self._turn:
            for client in list(self._clients):
                if not client.dead:
                    self._read(client, until_empty=True)

    def _accept(self, selector) -> None:
        for _ in range(_ACCEPTS_PER_TURN):
            try:
                sock, peer = self._listener.accept()
            except BlockingIOError:
                return
            except OSError as exc:                           # e.g. EMFILE: refuse, do not spin
                if exc.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    self.counters.clients_refused += 1
                    log.warning("socketcand hub: cannot accept a client: %s", exc)
                    time.sleep(_SELECT_TIMEOUT)
                return
            if len(self._clients) >= MAX_CLIENTS:
                self.counters.clients_refused += 1
                self._close_socket(sock)
                continue
            sock.setblocking(False)
            try:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, CLIENT_SEND_BUFFER)
            except OSError:
                pass
            client = _Client(sock=sock, peer=peer, accepted=time.monotonic())
            self.counters.clients_accepted += 1
            client.replies += b"< hi >"
            self._clients = self._clients + [client]
            selector.register(sock, selectors.EVENT_READ, client)
            log.info("socketcand hub: client %s connected", peer)

    def _read(self, client: _Client, until_empty: bool = False) -> None:
        """Take in what the client sent: up to _READS_PER_TURN reads, a short one ending the turn (the selector
        says when more comes); `until_empty` reads until the socket has nothing (a segment can reach it while the
        socket thread holds it, and comes after a short read: 33 of 40 frames at a wake-up)."""
        for _ in range(_READS_PER_TURN * (64 if until_empty else 1)):
            try:
                data = client.sock.recv(_RECV_SIZE)
            except BlockingIOError:
                return
            except OSError:
                data = b""
            if not data:
                self._kill(client, "disconnected")
                return
            try:    # acknowledge at once: a client without TCP_NODELAY (python-can's default) holds its
                    # next small frame until our ACK (Nagle), and Linux delays ACKs up to 40 ms
                client.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_QUICKACK, 1)
            except OSError:
                pass
            client.buffer += data.decode("ascii", errors="replace")
            self._parse(client)
            if client.dead or (len(data) < _RECV_SIZE and not until_empty):
                return

    def _parse(self, client: _Client) -> None:
        buf = client.buffer
        while buf and not client.dead:
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
                    log.debug("socketcand hub: client %s sent an endless command; closing it", client.peer)
                    self._kill(client, "endless command")
                    buf = ""
                break
            inner = buf[start + 1:end]
            buf = buf[end + 1:]
            if "<" in inner:                                  # an unterminated command before
                self.counters.garbage_commands += 1
                inner = inner[inner.rfind("<") + 1:]
            self._command(client, inner.split())
        client.buffer = buf

    def _reply(self, client: _Client, text: str) -> None:
        if len(client.replies) + len(text) > MAX_REPLY_BYTES:
            self._drop_slow(client, "does not read its replies")
            return
        client.replies += text.encode("ascii")

    def _command(self, client: _Client, tokens: list[str]) -> None:
        verb = tokens[0] if tokens else ""
        if verb == "open" and len(tokens) == 2 and client.state == "greeted":
            if tokens[1] == self.channel:
                client.state = "open"
                self._reply(client, "< ok >")
            else:
                self._reply(client, "< error could not open bus >")
        elif verb == "rawmode" and len(tokens) == 1 and client.state in ("open", "raw"):
            if client.state != "raw":
                client.cursor = self._log.head                # frames from now on
            client.raw_since = time.monotonic()
            client.state = "raw"
            self._reply(client, "< ok >")
        elif verb == "echo" and len(tokens) == 1:
            self._reply(client, "< echo >")
        elif verb == "send" and client.state in ("open", "raw"):
            try:
                msg = parse_send(tokens)
            except ValueError as exc:
                self.counters.garbage_commands += 1
                log.debug("socketcand hub: dropped %r: %s", " ".join(tokens), exc)
                return
            self.counters.frames_from_clients += 1
            msg.channel, msg.is_rx = self.channel, True
            for bus in self._local_buses:         # one frame object for all: a receiver does not change it
                bus.deliver(msg)
            self._publish(msg, origin=client)
        else:
            self.counters.garbage_commands += 1
            log.debug("socketcand hub: dropped unknown command %r", " ".join(tokens))

    def _flush(self, selector) -> None:
        """One turn: every client's new frames into its buffer, then what its socket takes."""
        now = time.monotonic()
        cursors = [c.cursor for c in self._clients if not c.dead and c.state == "raw"]
        first, entries = self._log.since(min(cursors, default=self._log.head))
        head = first + len(entries)
        for client in self._clients:
            if client.dead:
                continue
            if client.state != "raw":
                if now - client.accepted > HANDSHAKE_TIMEOUT:
                    self.counters.handshake_timeouts += 1
                    self._kill(client, "no handshake")
                    continue
            elif now - client.raw_since >= RAWMODE_GRACE and client.cursor < head:
                if client.cursor < first:
                    self._drop_slow(client, f"fell {head - client.cursor} frames behind")
                    continue
                if len(client.output) < MAX_OUTPUT_BYTES:
                    taken = [data for origin, data in entries[client.cursor - first:] if origin is not client]
                    client.cursor = head
                    client.output += b"".join(taken)
                    self.counters.frames_to_clients += len(taken)
            if client.writable and (client.replies or client.output):
                self._send(client, selector)
        dead = [c for c in self._clients if c.dead]
        if dead:
            self._clients = [c for c in self._clients if not c.dead]
            for client in dead:
                try:
                    selector.unregister(client.sock)
                except (KeyError, ValueError):
                    pass
                self._close_socket(client.sock, reset=client.slow)
                self.counters.clients_closed += 1
                log.info("socketcand hub: client %s closed (%s)", client.peer, client.reason)

    def _send(self, client: _Client, selector) -> None:
        """Send what the kernel takes without waiting; the rest waits for EVENT_WRITE."""
        for buffer in (client.replies, client.output):
            if not buffer:
                continue
            try:
                sent = client.sock.send(buffer)
            except BlockingIOError:
                sent = 0
            except OSError as exc:
                self._kill(client, f"send failed: {exc}")
                return
            del buffer[:sent]
            if buffer:                                        # the kernel is full: wait for it
                client.writable = False
                if not client.watch_write:
                    client.watch_write = True
                    selector.modify(client.sock, selectors.EVENT_READ | selectors.EVENT_WRITE, client)
                return
        if client.watch_write:
            client.watch_write = False
            selector.modify(client.sock, selectors.EVENT_READ, client)

    def _drop_slow(self, client: _Client, reason: str) -> None:
        if not client.dead:
            self.counters.slow_clients_dropped += 1
            client.slow = True
            self._kill(client, reason)

    def _kill(self, client: _Client, reason: str) -> None:
        """Mark a client for closing at the end of this turn (socket thread only)."""
        if not client.dead:
            client.dead = True
            client.reason = reason

    # ------------------------------------------------------------------ frames to clients

    def _publish(self, msg: can.Message, origin: _Client | None) -> None:
        """Append a frame to the log (the socket thread sends it on its next turn)."""
        text = format_frame(msg)
        if text is None:
            self.counters.dropped_frames += 1
            return
        self._log.append(origin, text.encode("ascii"))

    @staticmethod
    def _close_socket(sock: socket.socket, reset: bool = False) -> None:
        """Close; `reset`: with a TCP reset, so the kernel does not keep unsent data for a
        client that does not read (a FIN would wait behind it)."""
        try:
            if reset:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            else:
                sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        sock.close()


class LocalBus(can.BusABC):
    """The hub's in-process side as a python-can bus: `recv` takes the frames of the clients and of the other
    local buses (queued by their senders, bounded like the clients' log: the oldest go), `send` hands a frame to
    them at once. No thread of its own."""

    def __init__(self, hub: SocketcandServer):
        self._hub = hub
        self._inbox: deque = deque(maxlen=MAX_QUEUED_FRAMES)
        self._arrived = threading.Condition()
        self._closed = False
        self.channel_info = f"socketcand hub {hub.host}:{hub.port} {hub.channel} (in-process)"
        super().__init__(channel=hub.channel)

    def deliver(self, msg: can.Message) -> None:
        """Queue a frame for this bus's receiver (any thread); the oldest goes, counted, when it left a whole
        log's worth unread."""
        if len(self._inbox) == MAX_QUEUED_FRAMES:
            self._hub.counters.local_frames_dropped += 1
        self._inbox.append(msg)
        with self._arrived:
            self._arrived.notify()

    def _recv_internal(self, timeout: float | None):
        if not self._inbox and timeout != 0 and not self._closed:
            with self._arrived:
                self._arrived.wait_for(lambda: self._inbox or self._closed, timeout)
        try:
            return self._inbox.popleft(), False
        except IndexError:
            return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._closed:
            raise can.CanOperationError("the hub's local bus is shut down")
        self._hub._from_local(msg, self)

    def shutdown(self) -> None:
        self._closed = True
        with self._arrived:
            self._arrived.notify_all()
        super().shutdown()
