"""The PLC writer: a thread beside the real-time loop.

``submit()`` (called by the loop) drops the newest pose into a slot and returns; the thread
writes it (latest pose wins: a pose not yet written is replaced by a newer one), or, when no
new pose comes, rewrites the block with the heartbeat advanced, so the heartbeat moves at least
every ``heartbeat_s``. The slot holds the newest pose with objects and, beside it, a newer frame
without any: so the last pose of a part that has just left the view is written before the empty
frame after it, never replaced by it. A lost PLC is reconnected with an exponential back-off;
each state change is logged once, never per frame.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field

from plc.block import BlockBuilder, Pose, Prepared, ms_u32
from plc.link import EXCEPTION_NAMES, Link, LinkDown, PlcRejected
from plc.options import PlcOptions, backoff_delays
from tracker.health import Health
from tracker.poses import FrameResult
from tracker.sources import Frame

log = logging.getLogger(__name__)

LATENCY_WINDOW = 4096

# States shown on the status line.
CONNECTING, CONNECTED, LOST, REJECTED, CLOSED = "connecting", "ok", "lost", "rejected", "closed"


@dataclass
class WriterStats:
    """Counters for the status line and the tests (written by the writer thread, read anywhere)."""

    submitted: int = 0  # poses handed over by the loop
    replaced: int = 0  # poses replaced in the slot by a newer one before they were written
    writes: int = 0  # blocks the PLC accepted (poses and heartbeats)
    poses_written: int = 0  # accepted blocks that carried a new pose (= seq)
    rejected: int = 0  # exception responses
    connects: int = 0
    losses: int = 0
    last_latency_ms: float = 0.0
    max_latency_ms: float = 0.0
    # Frame arrival -> its pose accepted by the PLC (ns), for the newest poses (a ring: flat memory).
    capture_to_register_ns: deque = field(default_factory=lambda: deque(maxlen=LATENCY_WINDOW))


class PlcWriter:
    """A ``tracker.runner.Sink`` writing registers 0-42 (contract section 4) through a ``Link``."""

    def __init__(self, link: Link, options: PlcOptions, health: Health, owned: tuple = (),
                 clock_ns=time.monotonic_ns) -> None:
        self.link = link
        self.options = options
        self.health = health
        self.stats = WriterStats()
        self.state = CONNECTING
        self._owned = owned  # things to stop after the final write (an embedded simulator)
        self._clock_ns = clock_ns
        self._builder = BlockBuilder(options.word_order)
        self._pending_pose: Pose | None = None  # newest unwritten pose with objects
        self._pending_empty: Pose | None = None  # newest unwritten frame without objects, newer than the above
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._lost_at = 0.0
        self._reject_code: int | None = None
        self._said_unreachable = False
        self._thread = threading.Thread(target=self._run, name="plc-writer", daemon=True)
        self._thread.start()

    # ---- called by the real-time loop: never blocks on the network ----
    def submit(self, frame: Frame, result: FrameResult) -> None:
        arrival_ns = frame.arrival_ns if frame.arrival_ns > 0 else self._clock_ns()
        pose = Pose(ms_u32(arrival_ns), result.objects, arrival_ns)
        with self._lock:
            replaced = self._pending_empty is not None
            if pose.objects:
                replaced += self._pending_pose is not None
                self._pending_pose, self._pending_empty = pose, None
            else:
                self._pending_empty = pose
            self.stats.replaced += replaced
            self.stats.submitted += 1
        self._wake.set()

    def status(self) -> str:
        s = self.stats
        if self.state == CONNECTED:
            return f"PLC ok {s.last_latency_ms:.1f} ms seq {self._builder.state.seq}"
        if self.state == REJECTED:
            return f"PLC rejected: exception {self._reject_code} ({EXCEPTION_NAMES.get(self._reject_code, '?')})"
        return f"PLC {self.state}"

    def close(self) -> None:
        """Final block with the running bit cleared (and the newest pose), then stop the thread."""
        self._stop.set()
        self._wake.set()
        # Worst case: one connect attempt and one write, each bounded by the request timeout.
        self._thread.join(timeout=3 * self.options.timeout_s + 1.0)
        if self._thread.is_alive():
            log.warning("PLC %s: the final write did not finish in time", self.link.name)
        self.link.close()
        for thing in self._owned:
            thing.stop()

    # ---- the writer thread ----
    def _take(self) -> Pose | None:
        """The oldest of the (at most two) pending frames: a pose before the empty frame after it."""
        with self._lock:
            if self._pending_pose is not None:
                pose, self._pending_pose = self._pending_pose, None
            else:
                pose, self._pending_empty = self._pending_empty, None
            if self._pending_empty is not None:
                self._wake.set()  # the empty frame after this pose is written next, not at the next heartbeat
        return pose

    def _put_back(self, pose: Pose) -> None:
        """A pose that did not reach the PLC stays the one to write, unless a newer one came meanwhile."""
        with self._lock:
            if pose.objects and self._pending_pose is None:
                self._pending_pose = pose
            elif not pose.objects and self._pending_pose is None and self._pending_empty is None:
                self._pending_empty = pose

    def _run(self) -> None:
        delays = backoff_delays(self.options.backoff_first_s, self.options.backoff_max_s)
        next_beat = 0.0
        while not self._stop.is_set():
            if not self.link.connected:
                if self._connect():
                    delays = backoff_delays(self.options.backoff_first_s, self.options.backoff_max_s)
                    next_beat = 0.0
                else:
                    self._stop.wait(next(delays))
                continue
            self._wake.wait(max(0.0, next_beat - time.monotonic()))
            self._wake.clear()
            if self._stop.is_set():
                break
            pose = self._take()
            if pose is None and time.monotonic() < next_beat:
                continue  # woken without a pose (a set() that raced with the last take)
            self._write(pose, running=True)
            next_beat = time.monotonic() + self.options.heartbeat_s
        self._final()

    def _final(self) -> None:
        if not self.link.connected and not self._connect():
            log.warning("PLC %s: not reachable at exit; the PLC will see the heartbeat stop", self.link.name)
            return
        pose, after = self._take(), self._take()
        if after is not None:  # a last pose and the empty frame after it: both, in order
            self._write(pose, running=True)
            pose = after
        if self._write(pose, running=False):
            log.debug("PLC %s: final status written (running bit cleared)", self.link.name)
        self.state = CLOSED

    def _connect(self) -> bool:
        try:
            self.link.connect()
        except LinkDown as exc:
            if self.stats.connects == 0 and not self._said_unreachable:
                self._said_unreachable = True
                log.warning("PLC %s: not reachable (%s); retrying with back-off up to %g s",
                            self.link.name, exc, self.options.backoff_max_s)
            return False
        self.stats.connects += 1
        o = self.options
        if self.stats.connects == 1:
            log.info("PLC %s: connected (unit %d, base %d, word order %s)",
                     self.link.name, o.unit, o.base, o.word_order.value)
        else:
            log.info("PLC %s: reconnected after %.1f s", self.link.name, time.monotonic() - self._lost_at)
        self.state = CONNECTED
        self._reject_code = None
        return True

    def _write(self, pose: Pose | None, running: bool) -> bool:
        prepared: Prepared = self._builder.prepare(pose, self.health, running, ms_u32(self._clock_ns()))
        t0 = time.perf_counter_ns()
        try:
            self.link.write(self.options.base, prepared.registers)
        except LinkDown as exc:
            self.link.close()
            if pose is not None:
                self._put_back(pose)
            if self.state != LOST:
                self.stats.losses += 1
                self._lost_at = time.monotonic()
                log.warning("PLC %s: connection lost (%s); reconnecting", self.link.name, exc)
            self.state = LOST
            return False
        except PlcRejected as exc:
            # The request reached the PLC and was refused: retrying the same pose would fail the same
            # way, so it is dropped; the next pose or heartbeat tries again at the normal rate.
            self.stats.rejected += 1
            if self._reject_code != exc.code:
                log.error("PLC %s: %s; check --plc-base/--plc-unit against the PLC program", self.link.name, exc)
            self._reject_code = exc.code
            self.state = REJECTED
            return False
        latency_ms = (time.perf_counter_ns() - t0) / 1e6
        self._builder.commit(prepared)
        s = self.stats
        s.writes += 1
        s.poses_written += prepared.new_pose
        s.last_latency_ms = latency_ms
        s.max_latency_ms = max(s.max_latency_ms, latency_ms)
        if prepared.new_pose and pose is not None and pose.arrival_ns:
            s.capture_to_register_ns.append(self._clock_ns() - pose.arrival_ns)
        if self.state == REJECTED:
            log.info("PLC %s: writes accepted again", self.link.name)
            self._reject_code = None
        self.state = CONNECTED
        return True
