"""The emulated EPOS2 (hopper_ros.canbus.epos2_emulator) against an independent CANopen master.

The master is the `canopen` library on python-can's virtual bus, with the EDS in test/data; the
drive runs in a thread at about 1 kHz of wall time with a rigid-body motor from
config/hardware.yaml, so a current setpoint really moves the motor. Deterministic checks (SYNC
timing, position mode, malformed frames) drive the emulator directly with a simulated clock.
The position regulator is checked on its own with a numerical simulation of the leg.
"""

from __future__ import annotations

import math
import struct
import threading
import time
import uuid
from pathlib import Path

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_emulator import Epos2Emulator
from hopper_ros.canbus.epos2_objects import Command, NmtState, OperationMode, SdoAbort, State
from hopper_ros.canbus.epos2_regulator import PositionGains, PositionRegulator
from hopper_ros.hardware.config import HardwareConfig, load_hardware

HARDWARE = load_hardware()
NODE = int(HARDWARE.drive.node_id)
EDS = Path(__file__).resolve().parent / "data" / "epos2.eds"
TIMEOUT = 5.0                 # [s] bound on every wait of these tests
MASTER_NODE = 0x7F            # the heartbeat producer the drive consumes in the tests


def unique_channel() -> str:
    return f"epos2-test-{uuid.uuid4().hex[:12]}"


# ------------------------------------------------------------------------------------ helpers


class MotorModel:
    """Rotor plus reflected leg inertia on the motor shaft, torque = k_t * current."""

    def __init__(self, hardware: HardwareConfig):
        m, enc = hardware.motor, hardware.encoders.motor
        self.inertia = m.leg_inertia / m.gear_ratio ** 2 + m.rotor_inertia   # [kg m^2]
        self.kt = m.torque_constant
        self.friction = m.viscous_friction
        self.counts_per_rad = enc.lines * enc.quadrature / (2.0 * math.pi)
        self.angle = 0.0   # [rad] motor shaft
        self.rate = 0.0    # [rad/s]
        self.current = 0.0

    def step(self, current: float, dt: float, load_torque: float = 0.0, substeps: int = 10) -> None:
        self.current = current
        h = dt / substeps
        for _ in range(substeps):
            acc = (self.kt * current - self.friction * self.rate - load_torque) / self.inertia
            self.rate += acc * h
            self.angle += self.rate * h

    @property
    def counts(self) -> int:
        return math.floor(self.angle * self.counts_per_rad)

    @property
    def rpm(self) -> float:
        return self.rate * 60.0 / (2.0 * math.pi)


class DriveLoop:
    """An Epos2Emulator and a MotorModel in a background thread, about 1 kHz of wall time."""

    def __init__(self, bus: can.BusABC, hardware: HardwareConfig = HARDWARE):
        self.lock = threading.Lock()
        self.motor = MotorModel(hardware)
        self.t0 = time.monotonic()
        with self.lock:
            self.drive = Epos2Emulator(bus, hardware)
        self.demands: list[float] = []
        self.peak_demand = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="epos2-drive-loop", daemon=True)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def _run(self) -> None:
        last = self.now()
        while not self._stop.is_set():
            now = self.now()
            with self.lock:
                self.drive.poll(now)
                demand = self.drive.control(now, self.motor.counts, self.motor.rpm, self.motor.current)
                self.demands.append(demand)
                self.peak_demand = max(self.peak_demand, abs(demand))
                del self.demands[:-100]
            self.motor.step(demand, now - last)
            last = now
            time.sleep(0.0005)

    def __enter__(self) -> "DriveLoop":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(TIMEOUT)

    def wait_for(self, condition, timeout: float = TIMEOUT) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                if condition(self.drive):
                    return True
            time.sleep(0.002)
        return False


@pytest.fixture
def rig():
    """(network, node, loop): the canopen master and the emulated drive on one virtual bus."""
    channel = unique_channel()
    drive_bus = can.Bus(interface="virtual", channel=channel)
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    node = canopen.RemoteNode(NODE, str(EDS))
    network.add_node(node)
    loop = DriveLoop(drive_bus)
    with loop:
        yield network, node, loop
    network.disconnect()
    drive_bus.shutdown()


def wait_emcy(node, code: int, timeout: float = TIMEOUT):
    """The first EMCY with `code` in the node's log (also one that came before the call)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for emcy in list(node.emcy.log):
            if emcy.code == code:
                return emcy
        time.sleep(0.005)
    raise AssertionError(f"no EMCY 0x{code:04X}; got {[hex(e.code) for e in node.emcy.log]}")


def wait_statusword(node, state: State, timeout: float = TIMEOUT) -> int:
    end = time.monotonic() + timeout
    while True:
        sw = node.sdo["Statusword"].raw
        if eo.decode_statusword(sw) == state or time.monotonic() > end:
            assert eo.decode_statusword(sw) == state, f"statusword 0x{sw:04X}, wanted {state}"
            return sw
        time.sleep(0.01)


class DirectRig:
    """The emulator on a virtual bus with a raw python-can peer and a simulated clock."""

    def __init__(self, hardware: HardwareConfig = HARDWARE):
        channel = unique_channel()
        self.peer = can.Bus(interface="virtual", channel=channel)
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.drive = Epos2Emulator(self.bus, hardware)
        self.motor = MotorModel(hardware)
        self.now = 0.0
        self.received: list[can.Message] = []

    def close(self) -> None:
        self.peer.shutdown()
        self.bus.shutdown()

    def send(self, cob: int, data: bytes = b"", **kwargs) -> None:
        self.peer.send(can.Message(arbitration_id=cob, data=data, is_extended_id=False, **kwargs))

    def tick(self, n: int = 1, dt: float = 1e-3, load_torque: float = 0.0) -> float:
        demand = 0.0
        for _ in range(n):
            self.drive.poll(self.now)
            demand = self.drive.control(self.now, self.motor.counts, self.motor.rpm, self.motor.current)
            self.motor.step(demand, dt, load_torque)
            self.now += dt
        self.drain()
        return demand

    def drain(self) -> list[can.Message]:
        while (msg := self.peer.recv(timeout=0)) is not None:
            self.received.append(msg)
        return self.received

    def frames(self, cob: int) -> list[can.Message]:
        self.drain()
        return [m for m in self.received if m.arbitration_id == cob]

    def sdo(self, payload: bytes) -> bytes:
        """One SDO request frame and the drive's answer."""
        self.drain()
        self.received.clear()
        self.send(eo.sdo_rx_cob_id(NODE), payload)
        self.drive.poll(self.now)
        answers = self.frames(eo.sdo_tx_cob_id(NODE))
        assert len(answers) == 1, answers
        return bytes(answers[0].data)

    def write(self, index: int, sub: int, fmt: str, value) -> None:
        raw = struct.pack(fmt, value)
        answer = self.sdo(struct.pack("<BHB", 0x23 | ((4 - len(raw)) << 2), index, sub) + raw.ljust(4, b"\0"))
        assert answer[0] == 0x60, f"write 0x{index:04X}:{sub} aborted 0x{struct.unpack_from('<I', answer, 4)[0]:08X}"

    def read(self, index: int, sub: int = 0) -> bytes:
        answer = self.sdo(struct.pack("<BHB4x", 0x40, index, sub))
        assert answer[0] & 0xE0 == 0x40 and answer[0] & 0x02, answer.hex()
        return answer[4:8 - ((answer[0] >> 2) & 3)]

    def abort_code(self, answer: bytes) -> int:
        assert answer[0] == eo.SDO_ABORT_BYTE, answer.hex()
        return struct.unpack_from("<I", answer, 4)[0]


@pytest.fixture
def direct():
    r = DirectRig()
    yield r
    r.close()


# ------------------------------------------------------------------------- object dictionary


def test_eds_in_test_data_matches_the_dictionary():
    assert EDS.read_text() == eo.eds_text(), "regenerate: test/data/epos2.eds = epos2_objects.eds_text()"


def test_statusword_values_decode_to_their_states():
    for state, sw in eo.STATUSWORD_OF_STATE.items():
        assert eo.decode_statusword(sw) is state
        assert eo.decode_statusword(sw | 0x0400 | 0x0200) is state      # target reached, remote


def test_cob_ids_follow_the_predefined_connection_set():
    assert [eo.tpdo_cob_id(n, 5) for n in range(1, 5)] == [0x185, 0x285, 0x385, 0x485]
    assert [eo.rpdo_cob_id(n, 5) for n in range(1, 5)] == [0x205, 0x305, 0x405, 0x505]
    assert (eo.emcy_cob_id(5), eo.sdo_tx_cob_id(5), eo.sdo_rx_cob_id(5), eo.heartbeat_cob_id(5)) == \
        (0x85, 0x585, 0x605, 0x705)
    with pytest.raises(ValueError):
        eo.tpdo_cob_id(1, 0)
    assert eo.split_pdo_mapping_entry(eo.pdo_mapping_entry(0x6040, 0, 16)) == (0x6040, 0, 16)


# ---------------------------------------------------------------- canopen master, in-process


def test_nmt_sdo_and_heartbeat_with_canopen_master(rig):
    network, node, loop = rig
    assert node.nmt.wait_for_heartbeat(TIMEOUT) == "PRE-OPERATIONAL"
    assert node.sdo[0x1000].raw == 0x00020192                       # device type (CiA 402 drive)
    assert node.sdo[0x1008].raw == "EPOS2"                          # segmented upload (5 bytes)
    assert node.sdo[0x1018][1].raw == eo.MAXON_VENDOR_ID
    assert node.sdo[0x6410][2].raw == round(HARDWARE.drive.current_limit * 1000)
    assert [node.sdo[0x60FB][s].raw for s in (1, 2, 3)] == [537, 2179, 705]
    assert node.sdo[0x1017].raw == round(HARDWARE.drive.heartbeat_period * 1000)
    node.nmt.state = "OPERATIONAL"
    assert node.nmt.wait_for_heartbeat(TIMEOUT) == "OPERATIONAL"
    node.nmt.state = "STOPPED"
    assert node.nmt.wait_for_heartbeat(TIMEOUT) == "STOPPED"
    with pytest.raises(canopen.SdoCommunicationError):               # no SDO while stopped
        node.sdo[0x1000].raw
    node.nmt.state = "PRE-OPERATIONAL"
    assert node.sdo[0x1000].raw == 0x00020192
    node.sdo[0x1017].raw = 0                                         # heartbeat off
    seen: list[bytes] = []
    network.subscribe(eo.heartbeat_cob_id(NODE), lambda cob, data, ts: seen.append(bytes(data)))
    node.nmt.state = "RESET"                                         # reset node: boot-up, defaults
    assert node.nmt.wait_for_heartbeat(TIMEOUT) == "PRE-OPERATIONAL"
    assert seen[0] == b"\x00"                                         # the boot-up message first
    assert node.sdo[0x1017].raw == round(HARDWARE.drive.heartbeat_period * 1000)


def test_state_machine_through_controlword_sdo(rig):
    network, node, loop = rig
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.SWITCH_ON_DISABLED
    for command, state in ((Command.SHUTDOWN, State.READY_TO_SWITCH_ON),
                           (Command.SWITCH_ON, State.SWITCHED_ON),
                           (Command.ENABLE_OPERATION, State.OPERATION_ENABLED),
                           (Command.QUICK_STOP, State.QUICK_STOP_ACTIVE),
                           (Command.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),
                           (Command.SHUTDOWN, State.READY_TO_SWITCH_ON),
                           (Command.SWITCH_ON_AND_ENABLE, State.OPERATION_ENABLED),
                           (Command.DISABLE_OPERATION, State.SWITCHED_ON),
                           (Command.SHUTDOWN, State.READY_TO_SWITCH_ON)):
        node.sdo["Controlword"].raw = command
        assert eo.decode_statusword(node.sdo["Statusword"].raw) is state, command
    assert node.sdo["Statusword"].raw == 0x0121                       # EPOS2 value of the state
    node.sdo["Modes of operation"].raw = OperationMode.CURRENT
    assert node.sdo["Modes of operation display"].raw == OperationMode.CURRENT


def test_current_setpoint_by_remapped_pdo_moves_the_motor(rig):
    network, node, loop = rig
    node.tpdo.read()
    node.rpdo.read()
    # the canopen library's standard remapping: disable, sub0 = 0, entries, count, enable
    for pdo, variables, trans_type in (
            (node.rpdo[1], ("Controlword", "Modes of operation", "Current mode setting value"), 255),
            (node.tpdo[1], ("Statusword", "Position actual value", "Current actual value"), 1)):
        pdo.clear()
        for name in variables:
            pdo.add_variable(name)
        pdo.trans_type = trans_type
        pdo.enabled = True
    node.rpdo.save()
    node.tpdo.save()
    assert node.sdo[0x1600][0].raw == 3 and node.sdo[0x1600][3].raw == 0x20300010
    assert node.sdo[0x1A00][3].raw == 0x60780010
    node.nmt.state = "OPERATIONAL"
    assert node.nmt.wait_for_heartbeat(TIMEOUT) == "OPERATIONAL"

    rpdo = node.rpdo[1]
    setpoint_ma = 1500
    for cw in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        rpdo["Controlword"].raw = cw
        rpdo["Modes of operation"].raw = OperationMode.CURRENT
        rpdo["Current mode setting value"].raw = setpoint_ma
        rpdo.transmit()
        time.sleep(0.01)
    assert loop.wait_for(lambda d: d.state is State.OPERATION_ENABLED)
    assert loop.wait_for(lambda d: d.demand == pytest.approx(setpoint_ma / 1000))
    start = loop.motor.counts
    time.sleep(0.1)
    before = node.tpdo[1].timestamp
    network.sync.transmit()
    end = time.monotonic() + TIMEOUT
    while node.tpdo[1].timestamp == before and time.monotonic() < end:
        time.sleep(0.002)
    tpdo = node.tpdo[1]
    assert eo.decode_statusword(tpdo["Statusword"].raw) is State.OPERATION_ENABLED
    assert tpdo["Position actual value"].raw > start + 1000             # 1.5 A for 0.1 s: many turns
    assert tpdo["Current actual value"].raw == setpoint_ma

    rpdo["Current mode setting value"].raw = 30000                       # above the 20 A limit
    rpdo.transmit()
    assert loop.wait_for(lambda d: d.demand == pytest.approx(HARDWARE.drive.current_limit))
    rpdo["Current mode setting value"].raw = -setpoint_ma
    rpdo.transmit()
    assert loop.wait_for(lambda d: d.demand == pytest.approx(-setpoint_ma / 1000))
    rpdo["Controlword"].raw = Command.QUICK_STOP                         # quick stop: no current
    rpdo.transmit()
    assert loop.wait_for(lambda d: d.state is State.QUICK_STOP_ACTIVE and d.demand == 0.0)
    rpdo["Controlword"].raw = Command.DISABLE_VOLTAGE
    rpdo.transmit()
    assert loop.wait_for(lambda d: d.state is State.SWITCH_ON_DISABLED and d.demand == 0.0)


def test_fault_emcy_and_fault_reset(rig):
    network, node, loop = rig
    node.sdo["Modes of operation"].raw = OperationMode.CURRENT
    node.sdo["Current mode setting value"].raw = 800
    for cw in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        node.sdo["Controlword"].raw = cw
    assert loop.wait_for(lambda d: d.demand == pytest.approx(0.8))
    node.emcy.reset()
    with loop.lock:
        loop.drive.inject_fault(eo.ERROR_OVER_CURRENT, loop.now())
    emcy = wait_emcy(node, eo.ERROR_OVER_CURRENT)
    assert emcy.register & eo.ErrorRegisterBit.CURRENT
    assert loop.wait_for(lambda d: d.demand == 0.0)
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.FAULT
    assert node.sdo["Error code"].raw == 0x2310
    assert node.sdo[0x1001].raw & (eo.ErrorRegisterBit.GENERIC | eo.ErrorRegisterBit.CURRENT)
    assert node.sdo[0x1003][1].raw == 0x2310 and node.sdo[0x1003][0].raw == 1
    node.sdo["Controlword"].raw = Command.ENABLE_OPERATION               # no way out but a reset
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.FAULT
    node.sdo["Controlword"].raw = Command.FAULT_RESET
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.SWITCH_ON_DISABLED
    wait_emcy(node, 0x0000)                                              # error reset EMCY
    assert node.emcy.active == []
    assert node.sdo["Error code"].raw == 0 and node.sdo[0x1001].raw == 0
    node.sdo[0x1003][0].raw = 0                                          # clear the history
    assert node.sdo[0x1003][0].raw == 0


def test_sdo_aborts_like_a_cia301_device(rig):
    network, node, loop = rig

    def abort_of(action) -> int:
        with pytest.raises(SdoAbortedError) as info:
            action()
        return info.value.code

    assert abort_of(lambda: node.sdo.upload(0x2345, 0)) == 0x06020000      # no such object
    assert abort_of(lambda: node.sdo.upload(0x1018, 9)) == 0x06090011      # no such sub-index
    assert abort_of(lambda: node.sdo.download(0x6041, 0, b"\x00\x00")) == 0x06010002   # read only
    assert abort_of(lambda: node.sdo.download(0x1000, 0, b"\0\0\0\0")) == 0x06010002   # const
    assert abort_of(lambda: node.sdo.download(0x6060, 0, b"\x01\x02")) == 0x06070010   # wrong size
    assert abort_of(lambda: node.sdo.download(0x6060, 0, b"\x05")) == 0x06090030       # no mode 5
    assert abort_of(lambda: node.sdo.download(0x1600, 1, struct.pack("<I", 0x60400010))) == 0x06010000
    node.sdo.download(0x1400, 1, struct.pack("<I", 0x80000000 | eo.rpdo_cob_id(1, NODE)))
    node.sdo.download(0x1600, 0, b"\x00")
    assert abort_of(lambda: node.sdo.download(0x1600, 1, struct.pack("<I", 0x60410010))) == 0x06040041
    assert abort_of(lambda: node.sdo.download(0x1600, 1, struct.pack("<I", 0x23450010))) == 0x06020000
    # a command specifier that does not exist, sent raw
    answers: list[bytes] = []
    network.subscribe(eo.sdo_tx_cob_id(NODE), lambda cob, data, ts: answers.append(bytes(data)))
    network.send_message(eo.sdo_rx_cob_id(NODE), bytes([0xE0, 0x00, 0x10, 0x00, 0, 0, 0, 0]))
    end = time.monotonic() + TIMEOUT
    while not answers and time.monotonic() < end:
        time.sleep(0.005)
    assert answers and answers[0][0] == 0x80 and struct.unpack_from("<I", answers[0], 4)[0] == 0x05040001
    assert node.sdo[0x1000].raw == 0x00020192                           # still serving


def test_heartbeat_consumer_timeout_faults_the_drive(rig):
    network, node, loop = rig
    node.sdo[0x1016][1].raw = MASTER_NODE << 16 | 50                      # 50 ms
    for _ in range(5):
        network.send_message(eo.heartbeat_cob_id(MASTER_NODE), bytes([NmtState.OPERATIONAL]))
        time.sleep(0.02)
    assert loop.wait_for(lambda d: d.state is State.SWITCH_ON_DISABLED)   # alive: no fault
    wait_emcy(node, eo.ERROR_LIFE_GUARD)                                   # the master went quiet
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.FAULT
    assert node.sdo["Error code"].raw == 0x8130
    node.sdo["Controlword"].raw = Command.FAULT_RESET
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.SWITCH_ON_DISABLED


def test_malformed_frames_never_kill_the_drive(rig):
    network, node, loop = rig
    node.nmt.state = "OPERATIONAL"
    node.nmt.wait_for_heartbeat(TIMEOUT)
    node.emcy.reset()
    garbage = [
        (eo.sdo_rx_cob_id(NODE), b"\x40\x00"),                 # SDO of 2 bytes
        (eo.NMT_COB_ID, b"\x01"),                              # NMT of 1 byte
        (eo.NMT_COB_ID, b"\x99\x01"),                          # no such NMT command
        (eo.SYNC_COB_ID, b"\x01\x02\x03"),                     # SYNC with 3 bytes
        (eo.rpdo_cob_id(1, NODE), b"\x0f"),                     # RPDO1 too short
        (eo.rpdo_cob_id(2, NODE), bytes(8)),                   # RPDO2 too long
        (0x7FF, bytes(range(8))),
    ]
    for cob, data in garbage:
        network.send_message(cob, data)
    network.bus.send(can.Message(arbitration_id=0x1FFFFFFF, data=b"\xff" * 8, is_extended_id=True))
    network.bus.send(can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=8, is_extended_id=False))
    wait_emcy(node, eo.ERROR_PDO_LENGTH)                                  # CiA 301: PDO length error
    assert loop.wait_for(lambda d: d.malformed_frames >= 6)
    assert node.sdo[0x1000].raw == 0x00020192
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.FAULT
    node.sdo["Controlword"].raw = Command.FAULT_RESET
    assert eo.decode_statusword(node.sdo["Statusword"].raw) is State.SWITCH_ON_DISABLED


# ------------------------------------------------------------------- direct, simulated clock


def test_sync_tpdos_and_sync_applied_rpdo(direct):
    r = direct
    r.send(eo.NMT_COB_ID, bytes([eo.NmtCommand.START, NODE]))
    r.tick()
    r.write(0x1401, 1, "<I", 0x80000000 | eo.rpdo_cob_id(2, NODE))         # RPDO2 applied at SYNC
    r.write(0x1401, 2, "<B", 1)
    r.write(0x1401, 1, "<I", eo.rpdo_cob_id(2, NODE))
    r.received.clear()
    r.send(eo.rpdo_cob_id(2, NODE), struct.pack("<Hi", Command.SHUTDOWN, 1234))
    r.tick()
    assert r.drive.state is State.SWITCH_ON_DISABLED                        # not yet
    assert r.frames(eo.tpdo_cob_id(1, NODE)) == []                          # no SYNC, no TPDO
    r.send(eo.SYNC_COB_ID)
    r.tick()
    assert r.drive.state is State.READY_TO_SWITCH_ON
    assert r.drive.value(eo.POSITION_MODE_SETTING_VALUE) == 1234
    tpdo1 = r.frames(eo.tpdo_cob_id(1, NODE))
    tpdo2 = r.frames(eo.tpdo_cob_id(2, NODE))
    assert len(tpdo1) == 1 and len(tpdo2) == 1
    assert struct.unpack("<Hi", tpdo1[0].data) == (0x0121, r.motor.counts)
    r.write(0x1800, 2, "<B", 2)                                             # every 2nd SYNC
    r.received.clear()
    for _ in range(4):
        r.send(eo.SYNC_COB_ID)
        r.tick()
    assert len(r.frames(eo.tpdo_cob_id(1, NODE))) == 2
    assert len(r.frames(eo.tpdo_cob_id(2, NODE))) == 4


def test_position_mode_regulates_to_the_setpoint(direct):
    r = direct
    r.send(eo.NMT_COB_ID, bytes([eo.NmtCommand.START, 0]))                 # broadcast
    r.write(eo.MODES_OF_OPERATION, 0, "<b", OperationMode.POSITION)
    target = 1444                                                           # 10 degrees at the leg
    for cw in (Command.SHUTDOWN, Command.SWITCH_ON, Command.ENABLE_OPERATION):
        r.send(eo.rpdo_cob_id(2, NODE), struct.pack("<Hi", cw, target))
        r.tick()
    assert r.drive.state is State.OPERATION_ENABLED
    r.tick(50)
    assert abs(r.motor.counts - target) <= 0.02 * target                    # settled within 50 ms
    r.tick(450)
    assert abs(r.motor.counts - target) <= 3
    assert r.drive.value(eo.FOLLOWING_ERROR_ACTUAL_VALUE) == target - r.motor.counts
    r.write(eo.MAX_FOLLOWING_ERROR, 0, "<I", 500)                           # a jump beyond it: fault
    r.send(eo.rpdo_cob_id(2, NODE), struct.pack("<Hi", Command.ENABLE_OPERATION, target + 2000))
    r.tick()
    assert r.drive.state is State.FAULT and r.drive.error_code == eo.ERROR_FOLLOWING
    assert r.tick() == 0.0
    emcy = r.frames(eo.emcy_cob_id(NODE))
    assert emcy and struct.unpack_from("<H", emcy[-1].data)[0] == 0x8611


def test_sdo_protocol_details(direct):
    r = direct
    name = r.sdo(struct.pack("<BHB4x", 0x40, eo.MANUFACTURER_DEVICE_NAME, 0))
    assert name[0] == 0x41 and struct.unpack_from("<I", name, 4)[0] == 5      # segmented, size 5
    seg = r.sdo(bytes([0x60]) + bytes(7))
    assert seg[0] == 0x00 | ((7 - 5) << 1) | 1 and seg[1:6] == b"EPOS2"
    assert r.abort_code(r.sdo(bytes([0x60]) + bytes(7))) == SdoAbort.UNKNOWN_COMMAND  # nothing open
    name = r.sdo(struct.pack("<BHB4x", 0x40, eo.MANUFACTURER_DEVICE_NAME, 0))
    assert r.abort_code(r.sdo(bytes([0x70]) + bytes(7))) == SdoAbort.TOGGLE_BIT_NOT_ALTERNATED
    # segmented download into a 2-byte object; then a wrong total size
    assert r.sdo(struct.pack("<BHBI", 0x21, eo.CONTROLWORD, 0, 2))[0] == 0x60
    assert r.sdo(bytes([0x00 | (5 << 1) | 1]) + struct.pack("<H", Command.SHUTDOWN) + bytes(5))[0] == 0x20
    assert r.drive.state is State.READY_TO_SWITCH_ON
    assert r.sdo(struct.pack("<BHBI", 0x21, eo.CONTROLWORD, 0, 4))[0] == 0x60
    answer = r.sdo(bytes([0x00 | (3 << 1) | 1]) + bytes(7))
    assert r.abort_code(answer) == SdoAbort.LENGTH_MISMATCH
    # expedited download without the size: the object's own size is taken
    assert r.sdo(struct.pack("<BHB", 0x22, eo.CONTROLWORD, 0) + struct.pack("<I", Command.SWITCH_ON))[0] == 0x60
    assert r.drive.state is State.SWITCHED_ON
    assert r.abort_code(r.sdo(struct.pack("<BHB4x", 0xC0, 0x1000, 0))) == SdoAbort.UNKNOWN_COMMAND  # block
    assert r.abort_code(r.sdo(struct.pack("<BHB4x", 0x40, 0x1018, 7))) == SdoAbort.SUBINDEX_DOES_NOT_EXIST
    r.send(eo.sdo_rx_cob_id(NODE), b"\x40\x00\x10")                         # 3 bytes: malformed
    r.drive.poll(r.now)
    assert r.abort_code(bytes(r.frames(eo.sdo_tx_cob_id(NODE))[-1].data)) == SdoAbort.UNKNOWN_COMMAND
    assert r.drive.malformed_frames == 1
    assert r.read(eo.DEVICE_TYPE) == struct.pack("<I", 0x00020192)


def test_pdo_mapping_rules(direct):
    r = direct
    tpdo2 = eo.TPDO_COMMUNICATION + 1
    r.write(tpdo2, 1, "<I", 0x80000000 | eo.tpdo_cob_id(2, NODE))
    r.write(eo.TPDO_MAPPING + 1, 0, "<B", 0)
    for sub, (index, bits) in enumerate(((0x6064, 32), (0x606C, 32), (0x6041, 16)), start=1):
        r.write(eo.TPDO_MAPPING + 1, sub, "<I", eo.pdo_mapping_entry(index, 0, bits))
    answer = r.sdo(struct.pack("<BHB", 0x2F, eo.TPDO_MAPPING + 1, 0) + bytes([3, 0, 0, 0]))
    assert r.abort_code(answer) == SdoAbort.PDO_LENGTH_EXCEEDED                 # 80 bits > 64
    r.write(eo.TPDO_MAPPING + 1, 0, "<B", 2)
    answer = r.sdo(struct.pack("<BHB", 0x23, tpdo2, 1) + struct.pack("<I", 0x80000000 | 0x3FF))
    assert answer[0] == 0x60                                                     # while disabled: any id
    r.write(tpdo2, 1, "<I", eo.tpdo_cob_id(2, NODE))
    answer = r.sdo(struct.pack("<BHB", 0x23, tpdo2, 1) + struct.pack("<I", 0x3FF))
    assert r.abort_code(answer) == SdoAbort.INVALID_VALUE                         # valid -> valid: no
    answer = r.sdo(struct.pack("<BHB", 0x2F, tpdo2, 2) + bytes([245, 0, 0, 0]))
    assert r.abort_code(answer) == SdoAbort.INVALID_VALUE                         # reserved type


def test_nmt_reset_node_restores_defaults_and_boots(direct):
    r = direct
    r.write(eo.PRODUCER_HEARTBEAT_TIME, 0, "<H", 0)
    r.write(eo.CONTROLWORD, 0, "<H", Command.SHUTDOWN)
    r.received.clear()
    r.send(eo.NMT_COB_ID, bytes([eo.NmtCommand.RESET_NODE, NODE]))
    r.tick()
    boot = r.frames(eo.heartbeat_cob_id(NODE))
    assert boot and boot[0].data == bytearray([0])
    assert r.drive.nmt_state is NmtState.PRE_OPERATIONAL
    assert r.drive.state is State.SWITCH_ON_DISABLED
    assert struct.unpack("<H", r.read(eo.PRODUCER_HEARTBEAT_TIME))[0] == 100
    r.send(eo.NMT_COB_ID, bytes([eo.NmtCommand.START, NODE + 1]))               # another node
    r.tick()
    assert r.drive.nmt_state is NmtState.PRE_OPERATIONAL


# -------------------------------------------------------------------- the position regulator


def leg_step(regulator: PositionRegulator, step_deg: float, load_torque_leg: float = 0.0,
             duration: float = 0.5) -> list[float]:
    """Leg angle [deg] each 1 ms of a position step, leg plus reflected rotor inertia."""
    motor = MotorModel(HARDWARE)
    n = HARDWARE.motor.gear_ratio
    setpoint = round(math.radians(step_deg) * n * motor.counts_per_rad)
    regulator.reset(motor.counts)
    angles = []
    for _ in range(round(duration / 1e-3)):
        current = regulator.update(setpoint, motor.counts)
        motor.step(current, 1e-3, load_torque=load_torque_leg / n, substeps=20)
        angles.append(math.degrees(motor.angle / n))
    return angles


def test_position_regulator_step_is_fast_and_well_damped():
    m = HARDWARE.motor
    inertia_leg = m.leg_inertia + m.rotor_inertia * m.gear_ratio ** 2
    assert inertia_leg == pytest.approx(7.7e-3, rel=0.02)
    angles = leg_step(PositionRegulator.from_hardware(HARDWARE), 10.0)
    overshoot = (max(angles) - 10.0) / 10.0
    outside = [k for k, a in enumerate(angles) if abs(a - 10.0) > 0.02 * 10.0]
    settling = (outside[-1] + 1) * 1e-3 if outside else 0.0
    assert settling < 0.050, settling
    assert overshoot < 0.15, overshoot
    assert abs(angles[-1] - 10.0) < 0.01
    down = leg_step(PositionRegulator.from_hardware(HARDWARE), -10.0)
    assert abs(down[-1] + 10.0) < 0.01


def test_position_regulator_integral_removes_a_constant_load():
    load = 3.0                                                              # [N m] at the hip
    angles = leg_step(PositionRegulator.from_hardware(HARDWARE), 0.0, load_torque_leg=load, duration=1.0)
    assert min(angles) < -0.05                                              # the load pushes it away
    assert abs(angles[-1]) < 0.005                                          # and the integral brings it back
    proportional_only = PositionRegulator(PositionGains(537, 0, 705), HARDWARE.drive.current_limit)
    offset = leg_step(proportional_only, 0.0, load_torque_leg=load, duration=1.0)
    assert abs(offset[-1]) > 10 * abs(angles[-1])


def test_position_regulator_limits_and_si_gains():
    reg = PositionRegulator.from_hardware(HARDWARE)
    assert reg.update(100000, 0) == pytest.approx(HARDWARE.drive.current_limit)
    assert reg.update(-100000, 0) == pytest.approx(-HARDWARE.drive.current_limit)
    kp, ki, kd = PositionGains(537, 2179, 705).si()
    assert (kp, ki, kd) == pytest.approx((537 / 4 * 1e-3, 2179 / 1.024 * 1e-3, 705e-6))
    reg.reset(0)
    leg_angle = 0.01
    assert reg.current(leg_angle, 0.0) == pytest.approx(
        kp * round(leg_angle * reg.counts_per_radian) + 2179 / 1024 * 1e-3 * round(leg_angle * reg.counts_per_radian))
