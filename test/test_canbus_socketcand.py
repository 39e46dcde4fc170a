"""The loopback-only socketcand hub (hopper_ros.canbus.socketcand_server).

python-can's own socketcand client talks to it over TCP on 127.0.0.1: frames between clients
and the in-process bus in both directions (11- and 29-bit identifiers, empty frames, error
frames), garbage and disconnects survived, non-loopback binds refused. Then the acceptance
run: the emulated EPOS2 behind the hub in this process, the independent `canopen` library as
master in another process (test/data/socketcand_canopen_master.py).
"""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_objects import State
from hopper_ros.canbus.socketcand_protocol import format_frame, loopback_host, parse_send
from hopper_ros.canbus.socketcand_server import MAX_QUEUED_FRAMES, SocketcandServer
from test_canbus_epos2 import EDS, HARDWARE, NODE, DriveLoop

DATA = Path(__file__).resolve().parent / "data"
TIMEOUT = 10.0


@pytest.fixture
def hub():
    server = SocketcandServer(host="127.0.0.1", port=0, channel="can0").start()
    yield server
    server.close()


def client(server: SocketcandServer, channel: str = "can0") -> can.BusABC:
    return can.Bus(interface="socketcand", host="127.0.0.1", port=server.port, channel=channel)


def recv_until(bus: can.BusABC, predicate, timeout: float = TIMEOUT) -> can.Message:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = bus.recv(timeout=0.05)
        if msg is not None and predicate(msg):
            return msg
    raise AssertionError("expected frame not received")


def wait(condition, timeout: float = TIMEOUT) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.01)
    return False


@pytest.mark.parametrize("host", ["0.0.0.0", "", "192.168.1.10", "10.0.0.1", "::1", "::", "example.com"])
def test_refuses_non_loopback_bind(host):
    with pytest.raises(ValueError, match="loopback only"):
        SocketcandServer(host=host, port=0)


def test_loopback_names_accepted():
    assert loopback_host("localhost") == "127.0.0.1"
    assert loopback_host("127.0.0.2") == "127.0.0.2"
    server = SocketcandServer(host="localhost", port=0)
    assert server.address[0] == "127.0.0.1" and server.port > 0
    server.close()
    server.close()                                                  # idempotent


def test_protocol_text_matches_python_can_client():
    from can.interfaces.socketcand.socketcand import (
        convert_ascii_message_to_can_message, convert_can_message_to_ascii_message)

    for msg in (can.Message(arbitration_id=0x181, data=b"\x37\x01\xff", is_extended_id=False),
                can.Message(arbitration_id=0x080, data=b"", is_extended_id=False),
                can.Message(arbitration_id=0x1ABCDE12, data=bytes(range(8)), is_extended_id=True)):
        parsed = convert_ascii_message_to_can_message(format_frame(msg))
        assert (parsed.arbitration_id, bytes(parsed.data), parsed.is_extended_id) == \
            (msg.arbitration_id, bytes(msg.data), msg.is_extended_id)
        sent = convert_can_message_to_ascii_message(msg)[1:-1].split()
        back = parse_send(sent)
        assert (back.arbitration_id, bytes(back.data), back.is_extended_id) == \
            (msg.arbitration_id, bytes(msg.data), msg.is_extended_id)
    error = convert_ascii_message_to_can_message(format_frame(can.Message(arbitration_id=0x4, is_error_frame=True)))
    assert error.is_error_frame
    assert format_frame(can.Message(arbitration_id=0x181, is_remote_frame=True, is_extended_id=False)) is None
    for bad in (["send", "800", "1", "1"], ["send", "123", "9"] + ["0"] * 9, ["send", "123", "2", "1"],
                ["send", "123", "1", "zz"], ["send", "123", "1", "100"], ["send", "123456789", "0"],
                ["send", "-1", "0"], ["send", "123"]):
        with pytest.raises(ValueError):
            parse_send(bad)


def test_frames_between_clients_and_the_local_bus(hub):
    local = hub.local_bus()
    a, b = client(hub), client(hub)
    try:
        assert wait(lambda: hub.client_count == 2)
        time.sleep(0.15)                                            # past the rawmode grace
        a.send(can.Message(arbitration_id=0x601, data=b"\x40\x00\x10\x00\x00\x00\x00\x00", is_extended_id=False))
        got = recv_until(b, lambda m: m.arbitration_id == 0x601)
        assert bytes(got.data) == b"\x40\x00\x10\x00\x00\x00\x00\x00" and not got.is_extended_id
        got = recv_until(local, lambda m: m.arbitration_id == 0x601)
        assert got.dlc == 8 and not got.is_extended_id
        a.send(can.Message(arbitration_id=0x1ABCDE12, data=b"\x01", is_extended_id=True))
        got = recv_until(b, lambda m: m.arbitration_id == 0x1ABCDE12)
        assert got.is_extended_id and bytes(got.data) == b"\x01"
        local.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))        # SYNC
        for bus in (a, b):
            got = recv_until(bus, lambda m: m.arbitration_id == 0x080)
            assert got.dlc == 0
        local.send(can.Message(arbitration_id=0x20000004, is_error_frame=True))
        assert recv_until(a, lambda m: m.is_error_frame).is_error_frame
        assert a.recv(timeout=0.1) is None or True                  # nothing of its own comes back
        assert hub.counters.garbage_commands == 0
        assert hub.counters.frames_from_clients == 2
    finally:
        a.shutdown()
        b.shutdown()
    assert wait(lambda: hub.client_count == 0)


def test_read_pending_takes_in_every_frame_that_has_reached_the_hub(hub):
    """The simulated robot woken from a stop calls `read_pending` before its drive counts the SYNCs that came
    meanwhile (Epos2Emulator.discard_syncs): every frame that has reached the hub's socket by then is on the local
    bus when it returns, whether or not the socket thread has run since. The client here sends each frame at once
    (TCP_NODELAY); python-can's client does not (Nagle holds a small frame until the last one is acknowledged), so
    a few of its frames may still be in transit at a wake-up, and are answered as frames that came after it."""
    local = hub.local_bus()
    with socket.create_connection(hub.address, timeout=TIMEOUT) as sender:
        sender.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sender.sendall(b"< open can0 >< rawmode >< send 000 2 01 01 >")
        recv_until(local, lambda m: m.arbitration_id == 0x000)      # the handshake is over
        for _ in range(40):
            sender.sendall(b"< send 080 0 >")                        # SYNC
        hub.read_pending()
        taken = 0
        while (frame := local.recv(timeout=0)) is not None:
            taken += frame.arbitration_id == 0x080
        assert taken == 40


def test_a_local_bus_that_is_not_read_keeps_the_newest_frames_and_counts_the_rest(hub):
    """Local buses hand frames to each other directly (no thread): one whose receiver stops reading keeps the last
    MAX_QUEUED_FRAMES, drops the oldest and counts them; the sender never hears its own frames."""
    sender, idle = hub.local_bus(), hub.local_bus()
    extra = 10
    for index in range(MAX_QUEUED_FRAMES + extra):
        sender.send(can.Message(arbitration_id=0x181, data=index.to_bytes(2, "little"), is_extended_id=False))
    assert sender.recv(timeout=0) is None
    first = idle.recv(timeout=0)
    assert int.from_bytes(first.data, "little") == extra and first.is_rx and first.channel == hub.channel
    assert hub.counters.local_frames_dropped == extra
    assert sum(1 for _ in iter(lambda: idle.recv(timeout=0), None)) == MAX_QUEUED_FRAMES - 1
    assert idle.recv(timeout=0.05) is None                    # empty: waits its timeout, then nothing


def test_wrong_channel_is_refused(hub):
    with pytest.raises(can.CanError):
        client(hub, channel="vcan7")


def test_a_client_whose_rawmode_answer_came_with_frames_connects_again():
    """python-can's client compares the hub's `< ok >` to rawmode byte for byte; a motor driver starved past
    RAWMODE_GRACE under make test's load read it with three heartbeats and raised. The driver's `open_transport`
    connects again (a server here answers the first connection so, the second as it should)."""
    from hopper_ros.canbus.driver.bus import Transport, open_transport

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(4)
    connections = []

    def serve():
        while len(connections) < 2:
            sock, _ = listener.accept()
            try:
                sock.sendall(b"< hi >")
                if not sock.recv(64):                                    # `wait_for_server`'s probe: gone
                    sock.close()
                    continue
            except OSError:
                sock.close()
                continue
            connections.append(sock)
            sock.sendall(b"< ok >")                                      # to < open can0 >
            sock.recv(64)                                                # < rawmode >
            sock.sendall(b"< ok >" if len(connections) == 2 else b"< ok >< frame 701 1.000000 7F >")

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    bus = open_transport(Transport("socketcand", "can0", "127.0.0.1", listener.getsockname()[1], None, 5.0))
    try:
        server.join(TIMEOUT)
        assert len(connections) == 2 and not server.is_alive()
    finally:
        bus.shutdown()
        for sock in connections:
            sock.close()
        listener.close()


def raw_client(server: SocketcandServer) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=TIMEOUT)
    assert sock.recv(64) == b"< hi >"
    sock.sendall(b"< open can0 >")
    assert sock.recv(64) == b"< ok >"
    sock.sendall(b"< rawmode >")
    assert sock.recv(64) == b"< ok >"
    return sock


def test_garbage_and_disconnects_are_survived(hub):
    good = client(hub)
    local = hub.local_bus()
    try:
        bad = raw_client(hub)
        junk = [b"hello there", b"< send 800 1 1 >", b"< send 123 9 0 0 0 0 0 0 0 0 0 >", b"< send 123 2 1 >",
                b"< send 123 1 zz >", b"< bogus command >", b"<>", b"\xff\xfe\x00< send 123 1 1 2 >",
                b"< open can0 >", b"< send 12 1 5 "]
        for chunk in junk:
            bad.sendall(chunk)
        bad.sendall(b">< send 1A5 2 de ad >< echo >")               # completes the last, then a good one
        assert bad.recv(64).startswith(b"< echo >")
        got = recv_until(good, lambda m: m.arbitration_id == 0x1A5)
        assert bytes(got.data) == b"\xde\xad"
        recv_until(local, lambda m: m.arbitration_id == 0x1A5)
        assert hub.counters.garbage_commands >= 9
        bad.close()                                                  # abrupt disconnect
        endless = raw_client(hub)
        endless.sendall(b"< send " + b"1" * 1000)                     # never terminated: closed
        endless.settimeout(TIMEOUT)
        assert endless.recv(64) == b""
        endless.close()
        half = socket.create_connection(("127.0.0.1", hub.port), timeout=TIMEOUT)
        half.close()                                                  # gone before the handshake
        assert wait(lambda: hub.client_count == 1)
        local.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
        assert bytes(recv_until(good, lambda m: m.arbitration_id == 0x701).data) == b"\x05"
    finally:
        good.shutdown()


def test_canopen_master_in_another_process_drives_the_emulated_epos2():
    with SocketcandServer(host="127.0.0.1", port=0, channel=HARDWARE.can.channel) as hub:
        with DriveLoop(hub.local_bus()) as loop:
            child = subprocess.Popen(
                [sys.executable, str(DATA / "socketcand_canopen_master.py"), str(hub.port), str(EDS), str(NODE)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
            lines: list[tuple[str, str]] = []
            try:
                for line in child.stdout:
                    key, _, value = line.strip().partition(" ")
                    lines.append((key, value))
                    if key == "inject":
                        with loop.lock:
                            loop.drive.inject_fault(int(value, 16), loop.now())
                        child.stdin.write("\n")
                        child.stdin.flush()
                status = child.wait(TIMEOUT)
            finally:
                if child.poll() is None:
                    child.kill()
                    child.wait(TIMEOUT)
            stderr = child.stderr.read()
            assert status == 0, f"{lines}\n{stderr}"
            got = dict(lines)
            statuswords = [v for k, v in lines if k == "statusword"]
            assert [v for k, v in lines if k == "heartbeat"] == ["PRE-OPERATIONAL", "OPERATIONAL"]
            assert got["device_type"] == "0x20192" and got["device_name"] == "EPOS2"
            assert got["rpdo1"] == "Controlword,Current_mode_setting_value"
            assert statuswords[:3] == ["0x121", "0x123", "0x137"]       # ready, switched on, enabled
            assert int(got["moved"]) > 1000                              # 1.5 A for 0.2 s turns the motor
            assert int(got["current_averaged"]) == pytest.approx(1500, abs=50)
            assert statuswords[3:] == ["0x108", "0x140", "0x140"]        # fault, reset, reset
            assert got["error_code"] == "0x2310" and got["abort"] == "0x6020000"
            assert [v for k, v in lines if k == "emcy"] == ["0x2310", "0x8210"]
            assert got["done"] == "ok"
            # the drive's side of the same run
            with loop.lock:
                drive = loop.drive
                assert loop.peak_demand == pytest.approx(1.5)
                assert drive.state is State.SWITCH_ON_DISABLED and drive.malformed_frames == 1
                assert drive.counters.emcy_sent >= 4                     # 2 errors, 2 resets
                assert drive.value(eo.ERROR_HISTORY, 1) == 0x8210 and drive.value(eo.ERROR_HISTORY, 2) == 0x2310
            assert hub.counters.frames_from_clients > 20 and hub.counters.garbage_commands == 0


# --------------------------------------------------------------------------- abuse (issue 17)

ATTACK_CLIENTS = 200
ATTACK_SECONDS = 10.0


def _phase_figures(line: str) -> dict[str, float]:
    name, *pairs = line.split()
    figures = {key: float(value) for key, value in (pair.split("=") for pair in pairs)}
    figures["phase"] = name
    return figures


class LoadClient:
    """test/data/socketcand_load_client.py: a canopen master in its own process (SYNC + SDO)."""

    def __init__(self, port: int):
        self.child = subprocess.Popen(
            [sys.executable, str(DATA / "socketcand_load_client.py"), str(port), str(EDS), str(NODE)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        line = self.child.stdout.readline().strip()
        assert line == "ready", f"load client: {line!r} {self.child.stderr.read() if not line else ''}"

    def start_phase(self, name: str, seconds: float) -> None:
        self.child.stdin.write(f"phase {name} {seconds}\n")
        self.child.stdin.flush()

    def result(self) -> dict:
        return _phase_figures(self.child.stdout.readline())

    def phase(self, name: str, seconds: float) -> dict:
        self.start_phase(name, seconds)
        return self.result()

    def abort(self) -> None:
        """End it now, mid-phase or not (its figures unread)."""
        if self.child.poll() is None:
            self.child.kill()
            self.child.wait(TIMEOUT)

    def close(self) -> None:
        if self.child.poll() is None:
            try:
                self.child.stdin.write("quit\n")
                self.child.stdin.flush()
                self.child.wait(TIMEOUT)
            except (OSError, subprocess.TimeoutExpired):
                self.child.kill()
                self.child.wait(TIMEOUT)


def test_clients_that_stop_reading_cannot_stall_the_hub():
    """200 clients enter raw mode and never read again, for 10 s (dropped ones reconnect at once);
    a well-formed canopen master in another process keeps every SDO round trip and gets its TPDO
    for the SYNCs it sends, during the attack and after it; the hub drops and counts the slow
    clients and greets new clients afterwards (it used to deadlock for good)."""
    from hub_attack import RawModeAttack, handshake

    with SocketcandServer(host="127.0.0.1", port=0, channel="can0") as hub:
        with DriveLoop(hub.local_bus()):
            load = LoadClient(hub.port)
            try:
                with RawModeAttack(hub.port, clients=ATTACK_CLIENTS) as attack:
                    assert wait(lambda: attack.connected >= ATTACK_CLIENTS, 30.0), attack.connected
                    during = load.phase("attack", ATTACK_SECONDS)
                reopened, failures = attack.reopened, attack.failures
                after = load.phase("after", 2.0)
            finally:
                load.close()
            for figures in (during, after):
                assert figures["sdo_failed"] == 0, figures
                assert figures["sdo_ok"] >= 0.25 * figures["syncs"] / 20, figures    # one SDO per 20 SYNC periods
                assert figures["tpdo1"] >= 0.5 * figures["syncs"], figures
                assert figures["tpdo_gap_max_ms"] < 2000.0, figures                   # never stalled
            assert hub.counters.slow_clients_dropped >= ATTACK_CLIENTS, (hub.counters, reopened)
            assert reopened >= ATTACK_CLIENTS and failures == 0, (reopened, failures)
            fresh = handshake(hub.port)                                               # served again
            fresh.close()
            with client(hub) as bus:
                recv_until(bus, lambda m: m.arbitration_id == 0x700 + NODE)           # the drive's heartbeat
            assert wait(lambda: hub.client_count == 0)
