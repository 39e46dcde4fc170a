"""Where the drive is: one transport selection for both ends of the CAN bus.

A `Transport` is python-can's own bus configuration (`interface`, `channel`, and `host`, `port`,
`bitrate` where the interface takes them), read from the `can:` section of hardware.yaml with the
node's overrides. The motor driver opens it as a client (`open_bus`); the simulated robot, from
its `can` parameter (`hub`, `virtual:CHANNEL`, `none`, `sim_transport`), sits on the other end of
the same transport (`open_drive_side`): for socketcand it serves the loopback hub the driver
connects to. socketcan (robot: can0), socketcand (the simulated robot's hub on 127.0.0.1),
virtual (one process); udp_multicast is refused: its packets leave the machine.
"""

from __future__ import annotations

import logging
import socket
import time
from dataclasses import dataclass, replace
from typing import Any, Callable

import can

from hopper_ros.hardware.config import CanBus

from .status import first_line

CONNECT_TIMEOUT = 30.0   # [s] for a socketcand server to accept (the simulated robot may start later)
HANDSHAKE_ATTEMPTS = 3   # python-can's socketcand client compares the server's answers byte for byte: one starved
                         #   past the hub's RAWMODE_GRACE read its rawmode < ok > with three heartbeats and raised
                         #   (make test's load, 2026-11-29); it connects again
DEFAULT_BITRATE = 1000000


@dataclass(frozen=True)
class Transport(CanBus):
    """python-can's bus arguments for the drive's bus: a `can:` section with the overrides applied."""

    connect_timeout: float = CONNECT_TIMEOUT   # [s]

    def bus_config(self) -> dict[str, Any]:
        """The keyword arguments of `can.Bus` (python-can's config) for this transport."""
        config: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if self.interface == "socketcand":
            if self.host is None or self.port is None:
                raise ValueError("CAN interface socketcand needs `host` and `port`")
            config.update(host=self.host, port=self.port, tcp_tune=True)
        elif self.interface not in ("socketcan", "virtual"):
            config["bitrate"] = int(self.bitrate or DEFAULT_BITRATE)
        return config


def select_transport(can_config: CanBus, **overrides: Any) -> Transport:
    """The transport of a `can:` section (hardware.yaml); values in `overrides` win unless empty."""
    cfg = can_config.given()
    cfg.update({k: v for k, v in overrides.items() if v not in (None, "", 0)})
    interface = str(cfg.get("interface") or "")
    if interface == "udp_multicast":
        raise ValueError("CAN interface udp_multicast is not allowed (it leaves loopback)")
    if not interface:
        raise ValueError("CAN config lacks `interface`")
    port = cfg.get("port")
    return Transport(interface, cfg.get("channel"), None if cfg.get("host") is None else str(cfg["host"]),
                     None if port is None else int(port), cfg.get("bitrate"),
                     float(cfg.get("connect_timeout") or CONNECT_TIMEOUT))


def sim_transport(setting: str, can_config: CanBus, port: int | None = None) -> Transport | None:
    """The transport the simulated robot's `can` parameter names: `hub` (the socketcand hub of
    hardware.yaml, on `port`), `virtual:CHANNEL` (python-can's in-process bus), `none` (None)."""
    if setting == "none":
        return None
    if setting.startswith("virtual:"):
        return select_transport(can_config, interface="virtual", channel=setting.split(":", 1)[1])
    if setting == "hub":
        hub = select_transport(can_config, interface="socketcand")
        return hub if port is None else replace(hub, port=int(port))
    raise ValueError(f"can must be 'hub', 'virtual:CHANNEL' or 'none', got {setting!r}")


def wait_for_server(host: str, port: int, timeout: float, cancelled: Callable[[], bool] = lambda: False) -> None:
    """Wait until a TCP server accepts on host:port (python-can's own retry spins a core for 10 s)."""
    end = time.monotonic() + timeout
    while not cancelled():
        try:
            socket.create_connection((host, port), timeout=1.0).close()
            return
        except OSError as exc:
            if time.monotonic() > end:
                raise OSError(f"no CAN server (socketcand) accepts on {host}:{port} after {timeout:.0f} s: {exc}") from None
            time.sleep(0.1)
    raise InterruptedError(f"stopped while waiting for the CAN server on {host}:{port}")


def open_transport(transport: Transport, cancelled: Callable[[], bool] = lambda: False) -> can.BusABC:
    """A python-can bus on `transport`, as a client (a socketcand server is waited for)."""
    config = transport.bus_config()
    if transport.interface == "socketcand":
        # python-can warns on every frame split across two TCP reads, a normal event: not ours to log
        logging.getLogger("can.interfaces.socketcand").setLevel(logging.ERROR)
        wait_for_server(transport.host, transport.port, transport.connect_timeout, cancelled)
    for attempt in range(1, HANDSHAKE_ATTEMPTS + 1):
        try:
            return can.Bus(**config)
        except can.CanError as exc:
            if transport.interface != "socketcand" or "Expected" not in str(exc) or attempt == HANDSHAKE_ATTEMPTS \
                    or cancelled():
                raise
            logging.getLogger(__name__).warning("CAN server %s:%s: handshake failed (%s); connecting again",
                                                transport.host, transport.port, first_line(exc))


def open_bus(can_config: CanBus, cancelled: Callable[[], bool] = lambda: False, **overrides: Any) -> can.BusABC:
    """A python-can bus from the `can:` section of hardware.yaml (values in `overrides` win)."""
    return open_transport(select_transport(can_config, **overrides), cancelled)


def open_drive_side(transport: Transport):
    """The drive's end of `transport`: (bus, closer, hub or None). For socketcand the loopback hub
    is served here (on the transport's host and port) and the drive sits on its local bus."""
    if transport.interface == "socketcand":
        from hopper_ros.canbus.socketcand_server import SocketcandServer

        server = SocketcandServer(host=transport.host, port=transport.port, channel=transport.channel)
        server.start()
        return server.local_bus(), server.close, server
    bus = can.Bus(**transport.bus_config())
    return bus, bus.shutdown, None
