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

from plc.block import U32_MASK, BlockBuilder, Pose, Prepared, ms_u32
from plc.encode import decode_u32, encode_queue
from plc.link import EXCEPTION_NAMES, Link, LinkDown, PlcRejected
from plc.options import PlcOptions, backoff_delays
from plc.queue import PickOrder, entry_fields
from plc.registers import QUEUE_ENTRIES, QUEUE_START, QUEUE_WORDS, TAKEN
from tracker.health import FAULT_POSES, Health
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
    queue_writes: int = 0  # queue blocks (100-219) the PLC accepted
    # Frame arrival -> the queue of that frame accepted by the PLC (ns).
    queue_capture_to_register_ns: deque = field(default_factory=lambda: deque(maxlen=LATENCY_WINDOW))
    taken_polls: int = 0  # reads of taken_id that were answered
    taken: int = 0  # taken_ids acted on (parts dropped from the queue)
    taken_ignored: int = 0  # taken_ids echoed but not in the queue


class PlcWriter:
    """A ``tracker.runner.Sink`` writing registers 0-44 and 100-219 (contract sections 4 and 4b) and
    reading 290-291 through a ``Link``."""

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
        self._order = PickOrder(options.min_belt_speed_mm_s)
        self._frame: Pose | None = None  # the newest frame written: the queue lists its parts
        self._taken: set[int] = set()  # ids the PLC took that are still tracked: never listed again
        self._echo: int | None = None  # the last taken_id acted on; None until first read (a stale one is ignored)
        # A taken_id left from an earlier run (track ids start at 1 again): while the PLC holds it, the part
        # of this run with that id is not offered, as the PLC's commit to it could not be seen (the same
        # value written again) and its echo would read as acted on: it would be picked twice.
        self._stale: int | None = None
        self._stale_said = False
        self._queue_seq = 0
        self._queue_key: tuple | None = None  # the last queue written, without its counters
        self._queue_due = 0.0  # monotonic time the queue must be rewritten even without changes
        self._queue_reject: str | None = None  # the PLC refused 100-219: only the block is written
        self._taken_reject: str | None = None  # the PLC refused to read 290-291: no handshake
        self._acked = False  # a write was acknowledged since the last (re)connect
        self._queue_last_capture: int | None = None
        self._taken_reject_text: str | None = None  # a refused read of 290-291 not yet logged
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
            text = f"PLC ok {s.last_latency_ms:.1f} ms seq {self._builder.state.seq} queue {self._queue_seq}"
            if self._queue_reject:
                text += f" (queue not written: {self._queue_reject})"
            elif self._taken_reject:
                text += f" (taken_id not read: {self._taken_reject})"
            return text
        if self.state == REJECTED:
            return f"PLC rejected: exception {self._reject_code} ({EXCEPTION_NAMES.get(self._reject_code, '?')})"
        return f"PLC {self.state}"

    def live_state(self) -> dict:
        """What the PLC was last given, for the live view (read from another thread: a snapshot)."""
        s = self.stats
        frame = self._frame
        return {
            "link": self.link.name, "state": self.state, "latency_ms": round(s.last_latency_ms, 2),
            "seq": self._builder.state.seq, "queue_seq": self._queue_seq, "writes": s.writes,
            "taken": s.taken, "taken_echo": self._echo, "queue_ids": [] if frame is None else
            [o.id for o in self._order.order(frame.objects, self._held())][:5],
            "queue_rejected": self._queue_reject,
        }

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
        try:
            self._loop()
        except Exception:  # a bug must not silence the PLC without a word, nor skip the final block
            log.exception("PLC %s: the writer failed; writing the final block", self.link.name)
            self.health.set_fault(FAULT_POSES)
        try:
            self._final()
        except Exception:
            log.exception("PLC %s: the final block could not be written", self.link.name)

    def _loop(self) -> None:
        fresh = lambda: backoff_delays(self.options.backoff_first_s, self.options.backoff_max_s)  # noqa: E731
        delays = fresh()
        next_beat = next_poll = 0.0
        while not self._stop.is_set():
            if not self.link.connected:
                if not self._connect():
                    self._stop.wait(next(delays))
                    continue
                next_beat = next_poll = 0.0
            now = time.monotonic()
            self._wake.wait(max(0.0, min(next_beat, next_poll, self._queue_due) - now))
            self._wake.clear()
            if self._stop.is_set():
                break
            pose = self._take()
            now = time.monotonic()
            taken_changed = False
            if now >= next_poll:
                taken_changed = self._poll_taken()
                next_poll = now + self.options.taken_poll_s
            if not self.link.connected:
                if pose is not None:
                    self._put_back(pose)  # the taken_id read found the link down: write it after reconnecting
            elif pose is not None or taken_changed or now >= next_beat:
                # A refused write is not retried before the next heartbeat either: no busy loop.
                self._write(pose, running=True, retake=taken_changed)
                next_beat = time.monotonic() + self.options.heartbeat_s
            elif now >= self._queue_due:
                self._write_queue()
            if self._acked:
                delays = fresh()
            elif not self.link.connected:
                # Every kind of failure waits before the next connect, not only a refused connect: a PLC
                # that accepts and closes at once must not be hammered (and logged) hundreds of times.
                self._stop.wait(next(delays))

    def _final(self) -> None:
        if not self.link.connected and not self._connect():
            log.warning("PLC %s: not reachable at exit; the PLC will see the heartbeat stop", self.link.name)
            return
        # The poses not yet written (a last pose and the empty frame after it: both, in order), as any
        # other; then the final status over the last of them, offering nothing (a last pose written only
        # there never reached the block: its fields stayed those of the pose before, found by CI).
        for pose in (self._take(), self._take()):
            if pose is not None:
                self._write(pose, running=True)
        if self._write(None, running=False, offer=False):
            log.debug("PLC %s: final status written (running bit cleared, the queue empty)", self.link.name)
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
        self._acked = False
        self._reject_code = None
        self._queue_reject = None  # the PLC program may have changed: try the queue again
        self._taken_reject = None
        if self.state != LOST:
            self.state = CONNECTING  # "ok" only once a write is acknowledged
        return True

    def _lost(self, exc: Exception) -> None:
        self.link.close()
        self._acked = False
        if self.state == CONNECTED:
            self.stats.losses += 1
            self._lost_at = time.monotonic()
            log.warning("PLC %s: connection lost (%s); reconnecting", self.link.name, exc)
        elif self.state == CONNECTING and self.stats.connects == 1:
            self._lost_at = time.monotonic()
            log.warning("PLC %s: accepts connections but does not answer writes (%s); retrying with back-off "
                        "up to %g s", self.link.name, exc, self.options.backoff_max_s)
        self.state = LOST

    def _acknowledged(self) -> None:
        """A write the PLC answered: only now is the link "ok"."""
        self._acked = True
        if self.state in (CONNECTING, LOST):
            o = self.options
            if self.stats.losses == 0 and self._lost_at == 0.0:
                log.info("PLC %s: connected (unit %d, base %d, word order %s)",
                         self.link.name, o.unit, o.base, o.word_order.value)
            else:
                log.info("PLC %s: reconnected after %.1f s", self.link.name, time.monotonic() - self._lost_at)
        self.state = CONNECTED

    # ---- the handshake (290-291) ----
    def _poll_taken(self) -> bool:
        """Read taken_id; True when the queue changes because of it (a part taken, or an id to echo)."""
        # Only once the block is acknowledged (a PLC refusing everything, a wrong base, gets one error line),
        # but for the baseline, read before anything is offered (see _stale).
        if self._taken_reject or self._queue_reject or not self.link.connected:
            return False
        if self.state != CONNECTED and self._echo is not None:
            return False
        try:
            words = self.link.read(self.options.base + TAKEN.address, TAKEN.words)
        except LinkDown as exc:
            self._lost(exc)
            return False
        except PlcRejected as exc:
            # Logged after the next queue write: a PLC without any queue registers gets one line, not two.
            self._taken_reject = f"exception {exc.code}"
            self._taken_reject_text = str(exc)
            return False
        self.stats.taken_polls += 1
        taken_id = decode_u32(words, self.options.word_order)
        if self._echo is None:
            # Whatever the PLC holds before our first queue is from an earlier run: echo it, act on nothing.
            self._echo = taken_id
            self._stale = taken_id or None
            return True
        if taken_id == self._echo:
            return False
        self._echo = taken_id
        self._stale = None  # the PLC wrote since: a part with the old id may be offered
        tracked = {o.id for o in self._frame.objects} if self._frame is not None else set()
        if taken_id in tracked and taken_id not in self._taken:
            self._taken.add(taken_id)
            self.stats.taken += 1
            log.debug("PLC %s: part %d taken", self.link.name, taken_id)
        elif taken_id != 0:
            self.stats.taken_ignored += 1
            log.info("PLC %s: taken_id %d is not in the queue; echoed and ignored", self.link.name, taken_id)
        return True

    # ---- writes ----
    def _held(self) -> set[int]:
        """Ids not offered to the PLC: those it took, and a stale taken_id's (see ``_stale``)."""
        if self._stale is None:
            return self._taken
        if not self._stale_said and self._frame is not None and any(o.id == self._stale for o in self._frame.objects):
            self._stale_said = True
            log.warning("PLC %s: part %d is not offered while taken_id (290-291) still holds %d from before this "
                        "run (a commit to it could not be told from the old value); it is offered once the PLC "
                        "writes another taken_id: clear taken_id to 0 when the tracker restarts",
                        self.link.name, self._stale, self._stale)
        return self._taken | {self._stale}

    def _write(self, pose: Pose | None, running: bool, retake: bool = False, offer: bool = True) -> bool:
        """The block (0-44), then the queue (100-219) when it changed or is due. ``retake``: the taken set
        changed, so the block reports the new first entry of the current frame. ``offer``: False at exit,
        where the queue is written empty (a PLC committing to a part then would wait for an echo in vain)."""
        if self._echo is None and self.link.connected:
            # The PLC's taken_id before the first part is offered: a stale one holds its id's part back.
            self._poll_taken()
            if not self.link.connected:
                if pose is not None:
                    self._put_back(pose)
                return False
        if pose is not None:
            self._frame = pose
            tracked = {o.id for o in pose.objects}
            self._taken &= tracked  # ids are never reused: a taken id that is no longer tracked is done with
        entries = self._order.order(self._frame.objects, self._held()) if self._frame is not None and offer else []
        block_pose = pose if pose is not None else (self._frame if retake or not offer else None)
        first = entries[0] if entries else None
        prepared: Prepared = self._builder.prepare(block_pose, self.health, running, ms_u32(self._clock_ns()),
                                                   first)
        t0 = time.perf_counter_ns()
        try:
            self.link.write(self.options.base, prepared.registers)
        except LinkDown as exc:
            if pose is not None:
                self._put_back(pose)
            self._lost(exc)
            return False
        except PlcRejected as exc:
            # The request reached the PLC and was refused: retrying the same pose would fail the same
            # way, so it is dropped; the next pose or heartbeat tries again at the normal rate.
            self.stats.rejected += 1
            if self._reject_code != exc.code:
                log.error("PLC %s: %s; check --plc-base/--plc-unit against the PLC program", self.link.name, exc)
            self._reject_code = exc.code
            self.state = REJECTED
            self._acked = True  # the PLC answers: no reconnect back-off
            return False
        latency_ms = (time.perf_counter_ns() - t0) / 1e6
        self._builder.commit(prepared)
        if self.state == REJECTED:
            log.info("PLC %s: writes accepted again", self.link.name)
            self._reject_code = None
        s = self.stats
        s.last_latency_ms = latency_ms
        # The link is "ok" before the write is counted: whoever reads the count (another thread) then
        # reads the status as ok too (a test saw 1 write and "PLC connecting" on a busy machine).
        self._acknowledged()
        s.writes += 1
        s.poses_written += prepared.new_pose
        s.max_latency_ms = max(s.max_latency_ms, latency_ms)
        if prepared.new_pose and pose is not None and pose.arrival_ns:
            s.capture_to_register_ns.append(self._clock_ns() - pose.arrival_ns)
        self._write_queue(entries)
        return True

    def _write_queue(self, entries: list | None = None) -> None:
        if self._queue_reject or not self.link.connected or self.state != CONNECTED:
            self._queue_due = time.monotonic() + self.options.queue_period_s
            return
        if self._echo is None:
            self._poll_taken()  # the PLC's taken_id before our first queue: the baseline, never acted on
        frame = self._frame
        if entries is None:
            entries = self._order.order(frame.objects, self._held()) if frame is not None else []
        listed = [entry_fields(o) for o in entries[:QUEUE_ENTRIES]]
        t_capture_ms = frame.t_capture_ms if frame is not None else 0
        echo = self._echo or 0
        key = (t_capture_ms, len(entries), echo, tuple(tuple(e.values()) for e in listed))
        if key == self._queue_key and time.monotonic() < self._queue_due:
            return
        seq = (self._queue_seq + 1) & U32_MASK
        header = {"queue_seq": seq, "queue_count": len(listed), "in_view": min(len(entries), 0xFFFF),
                  "t_capture_ms": t_capture_ms, "taken_echo": echo, "t_write_ms": ms_u32(self._clock_ns())}
        registers = encode_queue(header, listed, self.options.word_order)
        assert len(registers) == QUEUE_WORDS
        try:
            self.link.write(self.options.base + QUEUE_START, registers)
        except LinkDown as exc:
            self._lost(exc)
            return
        except PlcRejected as exc:
            self._queue_reject = f"exception {exc.code}"
            self._taken_reject_text = None
            log.error("PLC %s: %s; the PLC has no queue registers: only registers 0-44 are written (no queue, "
                      "no taken_id handshake)", self.link.name, exc)
            return
        if self._taken_reject_text:
            log.error("PLC %s: %s; taken_id is not read: parts are never dropped from the queue",
                      self.link.name, self._taken_reject_text)
            self._taken_reject_text = None
        self._queue_seq = seq
        self._queue_key = key
        self._queue_due = time.monotonic() + self.options.queue_period_s
        self.stats.queue_writes += 1
        if frame is not None and frame.arrival_ns and key[0] != (self._queue_last_capture or 0):
            self.stats.queue_capture_to_register_ns.append(self._clock_ns() - frame.arrival_ns)
        self._queue_last_capture = key[0]
