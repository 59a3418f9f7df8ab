"""A stand-in for the arm's side of the queue handshake (contract section 4b), for ``tracker plc-sim
--arm-every MS`` and the demo: every period it takes the first listed part, writes its id to
``taken_id`` (290-291) and waits for the tracker's echo, as the PLC program in the README does.

It works on the simulator's own registers (it *is* the PLC), so it needs no connection of its own.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

from plc.encode import WordOrder, decode_queue, decode_u32, encode_u32
from plc.registers import QUEUE_FIELDS, QUEUE_START, QUEUE_WORDS, TAKEN

log = logging.getLogger(__name__)

# How long the arm waits for the echo before it gives up on that part (the contract promises 100 ms).
ECHO_TIMEOUT_S = 1.0
# How often it looks for the echo.
ECHO_POLL_S = 0.002


@dataclass(frozen=True)
class Take:
    """One part the arm took: the entry as read, and how long the echo took (None: no echo)."""

    id: int
    x_mm: float
    y_mm: float
    queue_seq: int
    echo_ms: float | None


class Arm:
    def __init__(self, sim, every_s: float, base: int = 0, word_order: WordOrder | None = None) -> None:
        if not every_s > 0:
            raise ValueError(f"arm: expected a period > 0 s, got {every_s}")
        self.sim = sim
        self.every_s = every_s
        self.base = base
        self.order = word_order or sim.word_order
        self.takes: list[Take] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="plc-sim-arm", daemon=True)

    def start(self) -> Arm:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=ECHO_TIMEOUT_S + 1.0)

    def _queue(self) -> dict:
        return decode_queue(self.sim.read(self.base + QUEUE_START, QUEUE_WORDS), self.order)

    def _echo(self) -> int:
        f = QUEUE_FIELDS["taken_echo"]
        return decode_u32(self.sim.read(self.base + f.address, f.words), self.order)

    def _run(self) -> None:
        while not self._stop.wait(self.every_s):
            if self.sim.running:
                self.take_first()

    def take_first(self) -> Take | None:
        """Latch the queue, take entry 0 (if any), write taken_id, wait for the echo."""
        queue = self._queue()
        if not queue["entries"]:
            return None
        entry = queue["entries"][0]
        part = int(entry["id"])
        self.sim.store(self.base + TAKEN.address, encode_u32(part, self.order))
        t0 = time.monotonic()
        echo_ms = None
        while time.monotonic() - t0 < ECHO_TIMEOUT_S:
            if self._echo() == part:
                echo_ms = (time.monotonic() - t0) * 1000
                break
            if self._stop.wait(ECHO_POLL_S):  # the arm's scan cycle
                break
        take = Take(part, float(entry["x_mm"]), float(entry["y_mm"]), int(queue["queue_seq"]), echo_ms)
        self.takes.append(take)
        if echo_ms is None:
            log.warning("%s arm: wrote taken_id %d; no echo within %g s", self.sim.label, part, ECHO_TIMEOUT_S)
        else:
            log.info("%s arm: took part %d at x %.1f mm y %.1f mm (queue_seq %d); echo after %.0f ms", self.sim.label,
                     part, take.x_mm, take.y_mm, take.queue_seq, echo_ms)
        return take
