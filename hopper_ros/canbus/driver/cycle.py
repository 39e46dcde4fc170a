"""The driver's 1 kHz loop in a thread of its own: `MotorDriver.cycle()` every SYNC period, every
received frame handled as it comes, the command watchdog tripped at its deadline (not up to a
period late), and the caller told of events and of fresh drive status. The motor_driver node runs
one; commands reach the driver from other threads under the same `lock`."""

from __future__ import annotations

import threading
import time
from typing import Callable

import can

from .driver import MotorDriver, first_line

Events = list[tuple[int, str]]


class CycleLoop:
    """Runs `driver` on its bus until `close()`. `on_events(events)` gets the driver's log lines,
    `on_status()` is called after every `status_decimation`-th complete set of TPDOs and at least
    every `status_period`, `on_error(text)` for an exception in the loop (which goes on: the
    drive's heartbeat consumer is the backstop)."""

    def __init__(self, driver: MotorDriver, lock: threading.Lock, on_events: Callable[[Events], None],
                 on_status: Callable[[], None], on_error: Callable[[str], None],
                 status_decimation: int = 1, status_period: float = 0.1):
        self.driver, self.lock = driver, lock
        self._on_events, self._on_status, self._on_error = on_events, on_status, on_error
        self.status_decimation, self.status_period = max(1, int(status_decimation)), status_period
        self.cycles = 0
        self.overruns = 0
        self.started = time.monotonic()
        self._tpdo_sets = 0
        self._last_status = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-cycle", daemon=True)

    def start(self) -> None:
        self.started = time.monotonic()
        self._thread.start()

    @property
    def rate(self) -> float:
        """Cycles per second since the start [Hz]."""
        return self.cycles / max(time.monotonic() - self.started, 1e-9)

    def close(self, join_timeout: float = 2.0) -> bool:
        """Stop the loop, shut the drive down (pumping the bus) and close the bus; True if the
        drive confirmed it is disabled."""
        if self._thread.is_alive():
            self._stop.set()
            self._thread.join(join_timeout)
        with self.lock:
            confirmed = self.driver.shutdown()
            events = self.driver.drain_events()
        self._on_events(events)
        self.driver.bus.shutdown()
        return confirmed

    def _status(self) -> None:
        self._on_status()
        self._last_status = time.monotonic()

    def _run(self) -> None:
        driver, bus = self.driver, self.driver.bus
        period = driver.settings.sync_period
        next_cycle = time.monotonic()
        while not self._stop.is_set():
            try:
                with self.lock:
                    driver.cycle()
                    events = driver.drain_events()
                if driver.transport_lost:
                    self._on_events(events)
                    return
                self.cycles += 1
                self._on_events(events)
                next_cycle += period
                if time.monotonic() - next_cycle > 5 * period:   # fell behind: skip, do not burst
                    self.overruns += 1
                    next_cycle = time.monotonic()
                while not self._stop.is_set():
                    now = time.monotonic()
                    remaining = next_cycle - now
                    if remaining <= 0:
                        break
                    with self.lock:
                        deadline = driver.watchdog_deadline()
                    if deadline <= now:                 # the command stream stopped: act now,
                        with self.lock:                 #   not at the next cycle
                            driver.watchdog()
                            events = driver.drain_events()
                        self._on_events(events)
                        continue
                    remaining = min(remaining, deadline - now + 1e-4)
                    try:
                        frame = bus.recv(timeout=remaining)
                    except (can.CanError, OSError, ValueError) as exc:
                        with self.lock:
                            driver.bus_error(f"receive failed: {first_line(exc)}", exc)
                        if driver.transport_lost:           # the hub went away: nothing will come any more
                            return
                        time.sleep(max(0.0, next_cycle - time.monotonic()))
                        break
                    if frame is None:
                        continue
                    with self.lock:
                        fresh = driver.handle(frame)
                    if fresh:
                        self._tpdo_sets += 1
                        if self._tpdo_sets % self.status_decimation == 0:
                            self._status()
                if time.monotonic() - self._last_status > self.status_period:
                    self._status()
            except Exception as exc:  # noqa: BLE001 - the cycle must go on (the drive's consumer is the backstop)
                self._on_error(f"CAN cycle: {type(exc).__name__}: {exc}")
                time.sleep(period)
