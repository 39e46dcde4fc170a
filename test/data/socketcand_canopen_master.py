"""CANopen master in its own process for test/test_canbus_socketcand.py.

Uses only python-can's socketcand client and the independent `canopen` library (no hopper_ros):
NMT, SDO, the CiA 402 state machine, a current setpoint by RPDO, SYNC and TPDO, a fault the
parent injects into the drive (handshake over stdin/stdout), fault reset, an SDO abort and a
malformed RPDO. Prints one `key value` line per observation; exit status 0 when done.

usage: python socketcand_canopen_master.py PORT EDS NODE_ID
"""

import sys
import time

from canopen.sdo.exceptions import SdoAbortedError
from canopen_client import connect

TIMEOUT = 5.0


def report(key, value) -> None:
    print(f"{key} {value}", flush=True)


def wait_emcy(node, code: int) -> None:
    end = time.monotonic() + TIMEOUT
    while time.monotonic() < end:
        if any(e.code == code for e in list(node.emcy.log)):
            return
        time.sleep(0.005)
    raise SystemExit(f"no EMCY 0x{code:04X}")


def sync_and_receive(network, node, pdos=(1, 2)) -> None:
    """Send a SYNC and wait until the TPDOs `pdos` came after it."""
    before = {n: node.tpdo[n].timestamp for n in pdos}
    network.sync.transmit()
    end = time.monotonic() + TIMEOUT
    while any(node.tpdo[n].timestamp == before[n] for n in pdos):
        if time.monotonic() > end:
            raise SystemExit("no TPDO after SYNC")
        time.sleep(0.002)


def state_after_command(node, before: str, heartbeats: int = 3) -> str:
    """The drive's NMT state from its heartbeats after an NMT command: one sent before the drive took the command
    (in flight, or the drive's loop a moment late under load) still says `before`, so up to `heartbeats` are read
    until one says otherwise (the drive's heartbeat period is 0.1 s: a drive that never switches still fails)."""
    state = node.nmt.wait_for_heartbeat(TIMEOUT)
    for _ in range(heartbeats - 1):
        if state != before:
            break
        state = node.nmt.wait_for_heartbeat(TIMEOUT)
    return state


def main() -> int:
    network, node = connect(sys.argv)
    try:
        report("heartbeat", node.nmt.wait_for_heartbeat(TIMEOUT))
        report("device_type", hex(node.sdo[0x1000].raw))
        report("device_name", node.sdo[0x1008].raw)

        node.rpdo.read()                              # the drive's default mapping, by SDO
        node.tpdo.read()
        report("rpdo1", ",".join(v.name.replace(" ", "_") for v in node.rpdo[1].map))
        node.nmt.state = "OPERATIONAL"
        report("heartbeat", state_after_command(node, "PRE-OPERATIONAL"))

        node.sdo["Modes of operation"].raw = -3       # Current Mode
        for command in (0x06, 0x07, 0x0F):            # shutdown, switch on, enable operation
            node.sdo["Controlword"].raw = command
            report("statusword", hex(node.sdo["Statusword"].raw))

        sync_and_receive(network, node)
        start = node.tpdo[1]["Position actual value"].raw
        rpdo = node.rpdo[1]
        rpdo["Controlword"].raw = 0x0F
        rpdo["Current mode setting value"].raw = 1500  # [mA]
        rpdo.transmit()
        time.sleep(0.2)
        sync_and_receive(network, node)
        report("moved", node.tpdo[1]["Position actual value"].raw - start)
        report("current_averaged", node.tpdo[2]["Current actual value averaged"].raw)

        report("inject", "0x2310")                    # the parent injects over current now
        sys.stdin.readline()
        wait_emcy(node, 0x2310)
        report("emcy", "0x2310")
        report("statusword", hex(node.sdo["Statusword"].raw))
        report("error_code", hex(node.sdo["Error code"].raw))
        node.sdo["Controlword"].raw = 0x80            # fault reset
        report("statusword", hex(node.sdo["Statusword"].raw))

        try:
            node.sdo.upload(0x2345, 0)
        except SdoAbortedError as exc:
            report("abort", hex(exc.code))
        network.send_message(0x200 + node.id, b"\x0f")   # RPDO1 one byte short
        wait_emcy(node, 0x8210)
        report("emcy", "0x8210")
        node.sdo["Controlword"].raw = 0x00            # fault reset acts on the rising edge of bit 7
        node.sdo["Controlword"].raw = 0x80
        report("statusword", hex(node.sdo["Statusword"].raw))
        report("done", "ok")
        return 0
    finally:
        network.disconnect()


if __name__ == "__main__":
    sys.exit(main())
