"""Our CANopen master primitives (hopper_ros.canbus.cia301.master) against the independent `canopen`
library: a canopen LocalNode with the EPOS2's object dictionary on a python-can `virtual` bus is
the SDO server, NMT slave, heartbeat and EMCY producer and the PDO decoder."""

from __future__ import annotations

import itertools
import struct
import time

import can
import canopen
import pytest
from canopen import objectdictionary as cod

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.cia301.master import (
    HeartbeatConsumer,
    MalformedFrame,
    PdoEntry,
    PdoMapping,
    SdoClient,
    SdoError,
    decode_emcy,
    nmt_frame,
    sync_frame,
)

NODE = 5
_channels = itertools.count()


def canopen_dictionary(node_id: int) -> cod.ObjectDictionary:
    """The EPOS2 object dictionary (epos2_objects) as a canopen ObjectDictionary."""
    od = cod.ObjectDictionary()
    od.node_id = node_id
    table = eo.object_dictionary(node_id)
    by_index: dict[int, list[eo.ODEntry]] = {}
    for entry in table.values():
        by_index.setdefault(entry.index, []).append(entry)

    def variable(entry: eo.ODEntry, index: int, subindex: int) -> cod.ODVariable:
        var = cod.ODVariable(entry.name, index, subindex)
        var.data_type = int(entry.data_type)
        var.access_type = entry.access.value
        var.default = entry.default
        var.pdo_mappable = entry.pdo_mappable
        return var

    for index, entries in sorted(by_index.items()):
        if len(entries) == 1 and entries[0].subindex == 0:
            od.add_object(variable(entries[0], index, 0))
            continue
        record = cod.ODRecord(f"Object 0x{index:04X}", index)
        for entry in sorted(entries, key=lambda e: e.subindex):
            record.add_member(variable(entry, index, entry.subindex))
        od.add_object(record)
    return od


@pytest.fixture
def peer():
    """(our bus, the canopen LocalNode drive, the canopen network) on a fresh virtual channel."""
    channel = f"master_test_{next(_channels)}"
    ours = can.Bus(interface="virtual", channel=channel)
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05                                     # quick teardown
    network.connect(interface="virtual", channel=channel)
    node = canopen.LocalNode(NODE, canopen_dictionary(NODE))
    network.add_node(node)
    yield ours, node, network
    network.disconnect()
    ours.shutdown()


def _answer(bus: can.BusABC, client: SdoClient, transfer, timeout: float = 2.0):
    """Pump SDO answers into the client until `transfer` is done (the LocalNode answers in its thread)."""
    end = time.monotonic() + timeout
    while not transfer.done:
        frame = bus.recv(timeout=0.05)
        now = time.monotonic()
        if frame is not None and frame.arbitration_id == client.rx_cob_id:
            client.on_frame(bytes(frame.data))
        client.poll(now)
        assert now < end, "no SDO answer"
    return transfer


def test_sdo_download_upload_and_abort_against_canopen_server(peer):
    bus, node, _ = peer
    client = SdoClient(NODE, bus.send, timeout=0.5)
    for index, sub, fmt, value in ((eo.MOTOR_DATA, eo.MOTOR_OUTPUT_CURRENT_LIMIT_SUB, "<H", 20000),
                                   (eo.POSITION_CONTROL_PARAMETERS, eo.GAIN_P_SUB, "<h", -537),
                                   (eo.MODES_OF_OPERATION, 0, "<b", -3),
                                   (eo.RPDO_MAPPING, 1, "<I", 0x60400010)):
        transfer = _answer(bus, client, client.download(index, sub, struct.pack(fmt, value), time.monotonic()))
        assert transfer.ok and not client.busy
        assert struct.unpack(fmt, node.data_store[index][sub])[0] == value      # the server stored it
        read = _answer(bus, client, client.upload(index, sub, time.monotonic()))
        assert read.ok and read.value(fmt) == value
    assert _answer(bus, client, client.upload(eo.DEVICE_TYPE, 0, time.monotonic())).value("<I") == eo.DEVICE_TYPE_VALUE

    missing = _answer(bus, client, client.download(0x5FFF, 0, b"\x01", time.monotonic()))
    assert isinstance(missing.error, SdoError) and missing.error.code == 0x06020000
    assert "does not exist" in missing.error.text
    read_only = _answer(bus, client, client.download(eo.STATUSWORD, 0, b"\x00\x00", time.monotonic()))
    assert read_only.error.code == 0x06010002 and "read only" in read_only.error.text
    wrong_size = _answer(bus, client, client.download(eo.CONTROLWORD, 0, b"\x06\x00\x00\x00", time.monotonic()))
    assert wrong_size.error.code == 0x06070010

    segmented = _answer(bus, client, client.upload(eo.MANUFACTURER_DEVICE_NAME, 0, time.monotonic()))
    assert segmented.error is not None and "segmented" in segmented.error.text   # "EPOS2" needs 5 bytes
    with pytest.raises(ValueError):
        client.download(eo.CONTROLWORD, 0, b"", time.monotonic())


def test_sdo_timeout_sends_abort_and_unexpected_answers_are_malformed(peer):
    bus, _, network = peer
    aborts = []
    network.subscribe(0x600 + 9, lambda cob, data, ts: aborts.append(bytes(data)))
    client = SdoClient(9, bus.send, timeout=0.05)                    # nobody is node 9
    transfer = client.upload(eo.STATUSWORD, 0, time.monotonic())
    _answer(bus, client, transfer)
    assert transfer.error.timed_out and transfer.error.code == 0x05040000
    deadline = time.monotonic() + 2.0
    while len(aborts) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert aborts[-1][0] == 0x80 and struct.unpack_from("<HBI", aborts[-1], 1) == (eo.STATUSWORD, 0, 0x05040000)

    client.download(eo.CONTROLWORD, 0, b"\x06\x00", 0.0)
    with pytest.raises(MalformedFrame) as failure:                   # an upload answer to a download
        client.on_frame(bytes([0x4B, 0x40, 0x60, 0x00, 0, 0, 0, 0]))
    assert failure.value.transfer is not None and failure.value.transfer.error is not None and not client.busy
    assert client.on_frame(bytes([0x60, 0x40, 0x60, 0x00, 0, 0, 0, 0])) is None   # not ours (idle)
    with pytest.raises(MalformedFrame):
        client.on_frame(b"\x60\x40")                                 # short frame


def test_nmt_commands_drive_canopen_slave_and_heartbeat_consumer_sees_it(peer):
    bus, node, _ = peer
    node.nmt.state = "PRE-OPERATIONAL"
    node.nmt.start_heartbeat(10)                                     # canopen's producer, 10 ms
    bus.send(nmt_frame(eo.NmtCommand.START, NODE))
    consumer = HeartbeatConsumer(NODE, timeout=0.1)
    deadline = time.monotonic() + 2.0
    while consumer.state != eo.NmtState.OPERATIONAL:
        frame = bus.recv(timeout=0.05)
        if frame is not None and frame.arbitration_id == consumer.cob_id:
            consumer.on_frame(bytes(frame.data), time.monotonic())
        assert time.monotonic() < deadline
    assert node.nmt.state == "OPERATIONAL" and consumer.alive
    assert not consumer.check(time.monotonic())
    bus.send(nmt_frame(eo.NmtCommand.ENTER_PRE_OPERATIONAL, NODE))
    time.sleep(0.05)
    assert node.nmt.state == "PRE-OPERATIONAL"
    node.nmt.stop_heartbeat()
    last = consumer.last_seen
    assert consumer.check(last + 0.05) is False
    assert consumer.check(last + 0.11) is True and not consumer.alive
    assert consumer.check(last + 0.5) is False                       # reported once per loss
    with pytest.raises(MalformedFrame):
        consumer.on_frame(b"\x05\x00", last)
    with pytest.raises(MalformedFrame):
        consumer.on_frame(b"\x33", last)
    silent = HeartbeatConsumer(NODE, timeout=0.1)
    silent.arm(10.0)
    assert silent.alive and not silent.check(10.05) and silent.check(10.2)   # never heard counts too


def test_pdo_mapping_written_by_sdo_is_decoded_by_canopen(peer):
    bus, node, network = peer
    mapping = PdoMapping.of([PdoEntry(eo.CONTROLWORD, 0, 16, False), PdoEntry(eo.MODES_OF_OPERATION, 0, 8, True),
                             PdoEntry(eo.POSITION_MODE_SETTING_VALUE, 0, 32, True)])
    client = SdoClient(NODE, bus.send, timeout=0.5)
    cob = eo.rpdo_cob_id(2, NODE)
    writes = [(eo.RPDO_COMMUNICATION + 1, 1, "<I", cob | eo.COB_ID_INVALID_BIT), (eo.RPDO_MAPPING + 1, 0, "<B", 0)]
    writes += [(eo.RPDO_MAPPING + 1, n, "<I", e.mapping) for n, e in enumerate(mapping.entries, 1)]
    writes += [(eo.RPDO_MAPPING + 1, 0, "<B", 3), (eo.RPDO_COMMUNICATION + 1, 1, "<I", cob)]
    for index, sub, fmt, value in writes:
        assert _answer(bus, client, client.download(index, sub, struct.pack(fmt, value), time.monotonic())).ok
    node.rpdo.read()                                                  # canopen reads the mapping back
    rpdo = node.rpdo[2]
    assert rpdo.enabled and rpdo.cob_id == cob and len(rpdo) == 3
    received = []
    rpdo.add_callback(lambda pdo: received.append((pdo[0].raw, pdo[1].raw, pdo[2].raw)))
    bus.send(can.Message(arbitration_id=cob, data=mapping.encode((0x000F, -1, -123456)), is_extended_id=False))
    deadline = time.monotonic() + 2.0
    while not received and time.monotonic() < deadline:
        time.sleep(0.01)
    assert received == [(0x000F, -1, -123456)]
    assert mapping.size == 7 and mapping.decode(mapping.encode((6, -3, 7))) == (6, -3, 7)
    with pytest.raises(MalformedFrame):
        mapping.decode(b"\x00" * 6)
    with pytest.raises(ValueError):
        mapping.encode((0x10000, 0, 0))                               # does not fit 16 bits
    with pytest.raises(ValueError):
        PdoMapping.of([PdoEntry(eo.POSITION_ACTUAL_VALUE, 0, 32, True)] * 3)   # 12 bytes


def test_emcy_from_canopen_producer_decodes_to_epos2_text(peer):
    bus, node, _ = peer
    node.emcy.send(eo.ERROR_OVER_CURRENT, 0x03, b"\x01\x02\x03\x04\x05")
    frame = bus.recv(timeout=2.0)
    assert frame.arbitration_id == eo.emcy_cob_id(NODE)
    emergency = decode_emcy(bytes(frame.data))
    assert (emergency.code, emergency.register, emergency.text) == (0x2310, 0x03, "Over current error")
    assert emergency.manufacturer == b"\x01\x02\x03\x04\x05" and not emergency.is_reset
    assert decode_emcy(bytes(8)).is_reset
    assert decode_emcy(struct.pack("<HB5x", 0xABCD, 1)).text == "Unknown error 0xABCD"
    with pytest.raises(MalformedFrame):
        decode_emcy(b"\x10\x23")
    assert sync_frame().arbitration_id == 0x80 and sync_frame().dlc == 0
