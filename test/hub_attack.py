"""The raw-mode no-read attack on the socketcand hub (issue 17), for the test and the bench.

`RawModeAttack(port, clients=200)` opens that many TCP connections to the hub on 127.0.0.1,
completes the socketcand handshake into raw mode on each, then never reads again. A connection
the hub closes (it fell behind and was dropped) is opened again at once, so that `clients`
non-reading clients stay connected for the whole attack. Everything is bounded: the number of
clients, the attack's duration (the caller's), each handshake's time (HANDSHAKE_TIMEOUT).
"""

from __future__ import annotations

import socket
import struct
import threading
import time

HANDSHAKE_TIMEOUT = 2.0
CHECK_PERIOD = 0.1          # [s] how often dropped connections are noticed and reopened
_TCP_ESTABLISHED = 1


def handshake(port: int, channel: str = "can0", timeout: float = HANDSHAKE_TIMEOUT) -> socket.socket:
    """A connection in raw mode (the hub's answers read exactly, as python-can does)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    try:
        for send, expect in ((None, b"< hi >"), (f"< open {channel} >".encode(), b"< ok >"),
                             (b"< rawmode >", b"< ok >")):
            if send:
                sock.sendall(send)
            got = b""
            while len(got) < len(expect):
                chunk = sock.recv(len(expect) - len(got))
                if not chunk:
                    raise ConnectionError("hub closed the connection during the handshake")
                got += chunk
            if got != expect:
                raise ConnectionError(f"hub answered {got!r}, expected {expect!r}")
    except BaseException:
        sock.close()
        raise
    return sock


def established(sock: socket.socket) -> bool:
    """True while the TCP connection is established (read from TCP_INFO, nothing is received)."""
    try:
        info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 8)
    except OSError:
        return False
    return struct.unpack("B", info[:1])[0] == _TCP_ESTABLISHED


class RawModeAttack:
    """`with RawModeAttack(port): ...`: the attack runs inside the block."""

    def __init__(self, port: int, clients: int = 200, channel: str = "can0"):
        self.port, self.clients, self.channel = port, clients, channel
        self.sockets: list[socket.socket] = []
        self.connected = 0            # handshakes completed in all
        self.reopened = 0             # connections the hub had closed, opened again
        self.failures = 0             # handshakes that failed (hub busy or refusing)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._maintain, name="hub-attack", daemon=True)

    def _open(self) -> socket.socket | None:
        try:
            sock = handshake(self.port, self.channel)
        except OSError:
            self.failures += 1
            return None
        sock.setblocking(False)
        self.connected += 1
        return sock

    def _maintain(self) -> None:
        while not self._stop.is_set() and len(self.sockets) < self.clients:
            sock = self._open()
            if sock is not None:
                self.sockets.append(sock)
        while not self._stop.wait(CHECK_PERIOD):
            for index, sock in enumerate(self.sockets):
                if self._stop.is_set():
                    return
                if not established(sock):
                    sock.close()
                    replacement = self._open()
                    if replacement is not None:
                        self.reopened += 1
                        self.sockets[index] = replacement

    def __enter__(self) -> "RawModeAttack":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(30.0)
        for sock in self.sockets:
            sock.close()
        self.sockets = []
