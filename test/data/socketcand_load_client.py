"""A well-formed CANopen master in its own process, measuring what it gets through the hub.

For the hub abuse test (test/test_canbus_socketcand.py) and bench/bench_robustness.py. Uses only
python-can's socketcand client and the independent `canopen` library (no hopper_ros). After
connecting it sets the drive OPERATIONAL and prints `ready`; then, for each line
`phase NAME SECONDS` read from stdin, it sends SYNC at 1 kHz from one thread and one SDO upload
(statusword) every 20 ms from another for SECONDS, and prints one line

    NAME syncs=N tpdo1=N sdo_ok=N sdo_failed=N sdo_p50_ms=X sdo_max_ms=X tpdo_gap_max_ms=X

(tpdo1: TPDO1 frames received, one per SYNC when all is well; tpdo_gap_max_ms: the longest
time without a TPDO1). `quit` ends it (exit status 0).

usage: python socketcand_load_client.py PORT EDS NODE_ID
"""

import statistics
import sys
import threading
import time

from canopen_client import connect

SYNC_PERIOD = 0.001
SDO_PERIOD = 0.02
SDO_TIMEOUT = 1.0


def run_phase(network, node, name: str, seconds: float) -> str:
    stats = {"tpdo1": 0, "last": None, "gap": 0.0}
    lock = threading.Lock()

    def on_tpdo(_cob_id, _data, _timestamp):
        now = time.monotonic()
        with lock:
            stats["tpdo1"] += 1
            if stats["last"] is not None:
                stats["gap"] = max(stats["gap"], now - stats["last"])
            stats["last"] = now

    stop = threading.Event()
    syncs = [0]

    def sync_loop():
        deadline = time.monotonic()
        while not stop.is_set():
            network.sync.transmit()
            syncs[0] += 1
            deadline += SYNC_PERIOD
            wait = deadline - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            elif wait < -0.05:
                deadline = time.monotonic()

    network.subscribe(0x180 + node.id, on_tpdo)
    start = time.monotonic()
    with lock:
        stats["last"] = start
    thread = threading.Thread(target=sync_loop, daemon=True)
    thread.start()
    ok, failed, times = 0, 0, []
    end = start + seconds
    while time.monotonic() < end:
        t0 = time.monotonic()
        try:
            node.sdo.upload(0x6041, 0)
            ok += 1
            times.append(time.monotonic() - t0)
        except Exception:  # noqa: BLE001 - a timeout or a garbled answer: counted
            failed += 1
        rest = SDO_PERIOD - (time.monotonic() - t0)
        if rest > 0:
            time.sleep(rest)
    stop.set()
    thread.join(2.0)
    network.unsubscribe(0x180 + node.id, on_tpdo)
    with lock:
        gap = max(stats["gap"], time.monotonic() - stats["last"])
        tpdo = stats["tpdo1"]
    p50 = statistics.median(times) * 1e3 if times else float("nan")
    worst = max(times) * 1e3 if times else float("nan")
    return (f"{name} syncs={syncs[0]} tpdo1={tpdo} sdo_ok={ok} sdo_failed={failed} "
            f"sdo_p50_ms={p50:.2f} sdo_max_ms={worst:.2f} tpdo_gap_max_ms={gap * 1e3:.1f}")


def main() -> int:
    network, node = connect(sys.argv, sdo_timeout=SDO_TIMEOUT)
    try:
        node.nmt.wait_for_heartbeat(5.0)
        node.nmt.state = "OPERATIONAL"
        node.nmt.wait_for_heartbeat(5.0)
        print("ready", flush=True)
        for line in sys.stdin:
            words = line.split()
            if not words or words[0] == "quit":
                break
            if words[0] == "phase":
                print(run_phase(network, node, words[1], float(words[2])), flush=True)
        return 0
    finally:
        network.disconnect()


if __name__ == "__main__":
    sys.exit(main())
