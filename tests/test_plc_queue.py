"""The queue of contract section 4b end to end: rendered scenes with several parts, the real writer, a real
Modbus TCP server, and mbpoll as the independent PLC (reading 100-219 in one request, writing 290-291)."""

from __future__ import annotations

import argparse
import logging
import math
import re
import subprocess
import threading
import time

import numpy as np
import pytest
from plc_support import (
    TRACKER,
    Rendered,
    ScriptedCamera,
    free_port,
    mbpoll,
    mbpoll_write_u32,
    queue_scene,
    require_mbpoll,
    run_loop,
    start_sim_process,
    stop_process,
    wait_until,
)

from plc.block import ms_u32
from plc.encode import WordOrder, decode_block, decode_queue, decode_u32, encode_u32
from plc.link import ModbusLink
from plc.options import PlcOptions
from plc.registers import QUEUE_START, QUEUE_WORDS, TAKEN
from plc.sim import PlcSimulator
from plc.sink import open_plc_sink
from plc.writer import PlcWriter
from tracker.cli_synth import write_scene
from tracker.health import Health
from tracker.pose_sink import PoseSink
from tracker.poses import FrameResult, TrackedObject, read_poses
from tracker.sources import Frame

BELT = (250.0, 120.0)  # queue_scene's belt velocity: the true direction of motion
NOT_LISTED = 9999  # a taken_id that is no part's


def f32(v: float) -> float:
    return float(np.float32(v))


def open_writer(mode: str, order: WordOrder, health: Health) -> tuple[PlcWriter, PlcSimulator, int]:
    """Client mode: the tracker writes into a simulator (the PLC). Server mode: the tracker's own server."""
    if mode == "client":
        sim = PlcSimulator(port=0, word_order=order).start()
        opts = PlcOptions("127.0.0.1", sim.port, word_order=order)
        return PlcWriter(ModbusLink(opts), opts, health, owned=(sim,)), sim, sim.port
    port = free_port()
    args = argparse.Namespace(no_plc=False, plc=f"127.0.0.1:{port}", plc_mode="server", plc_unit=1, plc_base=0,
                              plc_word_order=order.value)
    writer = open_plc_sink(args, health, demo=False)
    return writer, writer._owned[0], port


def read_queue_mbpoll(port: int, order: WordOrder) -> tuple[list[int], dict]:
    """Registers 100-219 in ONE read request, as the PLC does."""
    raw = mbpoll(port, QUEUE_START, QUEUE_WORDS, "4:hex", big_endian=order is WordOrder.ABCD)
    words = [int(raw[QUEUE_START + i], 16) for i in range(QUEUE_WORDS)]
    return words, decode_queue(words, order)


def expected_queue(objects: list[dict], taken: set[int]) -> list[dict]:
    """Independent pick order: furthest along the true belt direction first."""
    ux, uy = BELT[0] / math.hypot(*BELT), BELT[1] / math.hypot(*BELT)
    listed = [o for o in objects if o["id"] not in taken]
    return sorted(listed, key=lambda o: -(o["x_mm"] * ux + o["y_mm"] * uy))


@pytest.mark.parametrize(("n_parts", "mode", "order"), [
    (2, "client", "ABCD"), (6, "client", "CDAB"), (3, "server", "ABCD"), (4, "server", "CDAB"),
])
def test_queue_and_handshake_end_to_end(n_parts, mode, order, tmp_path):
    wo = WordOrder(order)
    big = wo is WordOrder.ABCD
    rendered = Rendered(queue_scene(n_parts))
    health = Health()
    writer, sim, port = open_writer(mode, wo, health)
    source = ScriptedCamera(rendered)
    seen: dict = {"snapshots": []}

    def arrival_ms(k: int) -> int:
        return ms_u32(source.arrival_ns[k])

    def settled_queue(k: int) -> dict:
        """Wait until the queue of frame k (the one just processed) is readable, read it with mbpoll."""
        def current():
            seen["words"], seen["queue"] = read_queue_mbpoll(port, wo)
            return seen["queue"]["t_capture_ms"] == arrival_ms(k)
        wait_until(current, f"the queue of frame {k}")
        seen["snapshots"].append((k, seen["words"]))
        return seen["queue"]

    def take_first(k: int) -> None:
        queue = settled_queue(k - 1)
        assert queue["queue_count"] >= 2, "the scene has several parts in view here"
        part = int(queue["entries"][0]["id"])
        mbpoll_write_u32(port, TAKEN.address, part, big)
        # The loop is held here: the writer thread alone must read taken_id, drop the part and echo it.
        wait_until(lambda: read_queue_mbpoll(port, wo)[1]["taken_echo"] == part, f"the echo of taken_id {part}")
        after = decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)
        block = decode_block(sim.read(0, 45), wo)
        assert [e["id"] for e in after["entries"]] == [e["id"] for e in queue["entries"][1:]][:5]
        assert after["in_view"] == queue["in_view"] - 1 and after["t_capture_ms"] == queue["t_capture_ms"]
        assert block["id"] == after["entries"][0]["id"], "the block reports the queue's new first entry"
        seen.setdefault("taken", []).append(part)

    def take_unknown(k: int) -> None:
        queue = settled_queue(k - 1)
        mbpoll_write_u32(port, TAKEN.address, NOT_LISTED, big)
        wait_until(lambda: read_queue_mbpoll(port, wo)[1]["taken_echo"] == NOT_LISTED, "the echo of an unknown id")
        after = decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)
        assert [e["id"] for e in after["entries"]] == [e["id"] for e in queue["entries"]], "echoed and ignored"

    third = take_first if n_parts > 2 else take_unknown
    source.hooks = {33: lambda: take_first(33), 40: lambda: take_unknown(40), 47: lambda: third(47)}
    poses_path = tmp_path / "poses.jsonl"
    summary = run_loop(source, [PoseSink(str(poses_path)), writer], health)
    assert summary.frames == 60
    lines = read_poses(poses_path)
    queue_writes = sim.writes(QUEUE_START)
    taken_writes = sim.writes(TAKEN.address)
    assert len(taken_writes) == len(source.hooks), "every taken_id was one write of 290-291"

    # Every queue the PLC received is one frame's queue: ids, x, y equal that frame's pose stream values,
    # in pick order, taken parts left out from their echo on, entries past queue_count all zero.
    frames_by_ms: dict[int, list[int]] = {}
    for k in range(len(lines)):
        frames_by_ms.setdefault(arrival_ms(k), []).append(k)
    taken: set[int] = set()
    seqs = []
    final = decode_queue(queue_writes[-1].values, wo)
    assert final["queue_count"] == final["in_view"] == 0, "at exit the queue is written empty"
    for w in queue_writes[:-1]:
        q = decode_queue(w.values, wo)
        seqs.append(q["queue_seq"])
        if q["taken_echo"] in seen.get("taken", []):
            taken.add(q["taken_echo"])
        got = [(e["id"], e["x_mm"], e["y_mm"]) for e in q["entries"]]
        assert q["queue_count"] == len(got) <= 5
        at = 10 + 22 * q["queue_count"]
        assert list(w.values[at:]) == [0] * (QUEUE_WORDS - at), "entries past queue_count are all zero"
        if q["t_capture_ms"] == 0:
            assert got == []  # before the first frame
            continue
        candidates = []
        for k in frames_by_ms.get(q["t_capture_ms"], []):
            want = expected_queue(lines[k]["objects"], taken)
            candidates.append(([(o["id"], f32(o["x_mm"]), f32(o["y_mm"])) for o in want[:5]], len(want)))
        assert (got, q["in_view"]) in candidates, f"queue {q['queue_seq']} is no frame's queue"
        for e in q["entries"]:
            # Flags: bit 1 only (its height still settling: auto, the default); no part is unpickable.
            assert e["flags"] & ~2 == 0 and e["reserved"] == 0 and e["measured"] in (0, 1)
            assert e["age_frames"] == 0 or not e["measured"]
    seqs.append(final["queue_seq"])
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), "queue_seq counts every queue write"
    assert set(seen["taken"]) == taken and len(taken) == (2 if n_parts > 2 else 1)
    # A taken part is never listed again, and the pose stream still reports it while in view.
    for part in taken:
        echoed = next(i for i, w in enumerate(queue_writes) if decode_queue(w.values, wo)["taken_echo"] == part)
        assert all(part not in [e["id"] for e in decode_queue(w.values, wo)["entries"]]
                   for w in queue_writes[echoed:])
    assert any(seen["taken"][0] in [o["id"] for o in line["objects"]] for line in lines[35:])
    # The pick order differs from id order in this scene: the test can tell them apart.
    assert any([e[0] for e in snap] != sorted(e[0] for e in snap) for snap in
               ([(e["id"],) for e in decode_queue(w.values, wo)["entries"]] for w in queue_writes))
    # mbpoll's snapshots (one request each) are exactly queues the tracker wrote: never half of two.
    written = {tuple(w.values) for w in queue_writes}
    assert seen["snapshots"] and all(tuple(words) in written for _, words in seen["snapshots"])
    assert decode_u32(sim.read(TAKEN.address, 2), wo) == NOT_LISTED or n_parts > 2
    assert writer.stats.taken == len(taken) and writer.stats.taken_ignored >= 1


def test_every_mbpoll_snapshot_is_one_queue_while_the_loop_runs(tmp_path):
    """An independent reader polling 100-219 as fast as it can while frames flow: each snapshot is a
    queue the tracker wrote as a whole."""
    require_mbpoll()
    wo = WordOrder.ABCD
    rendered = Rendered(queue_scene(4))
    writer, sim, port = open_writer("client", wo, Health())
    stop = threading.Event()
    snaps: list[list[int]] = []

    def reader():
        while not stop.is_set():
            snaps.append(read_queue_mbpoll(port, wo)[0])

    # Pace the camera on the writer: each frame waits until the previous frame's queue is written,
    # so the reader sees many different queues.
    source = ScriptedCamera(rendered)
    thread = threading.Thread(target=reader, daemon=True)

    def paced(k: int) -> None:
        wait_until(lambda: decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)["t_capture_ms"]
                   == ms_u32(source.arrival_ns[k - 1]), f"queue of frame {k - 1}")
        if k == 59:  # the reader stops before the writer and its server do
            stop.set()
            thread.join(timeout=10)

    source.hooks = {k: (lambda k=k: paced(k)) for k in range(1, 60)}
    thread.start()
    try:
        run_loop(source, [writer])
    finally:
        stop.set()
        thread.join(timeout=10)
    written = {tuple(w.values) for w in sim.writes(QUEUE_START)}
    counts = {decode_queue(s, wo)["queue_count"] for s in snaps}
    assert len(snaps) >= 5 and all(tuple(s) in written for s in snaps)
    assert max(counts) >= 2, "snapshots with several parts were taken"


def test_plc_without_queue_registers_gets_the_block_and_one_line(caplog):
    caplog.set_level(logging.INFO)
    rendered = Rendered(queue_scene(2, n_frames=40))
    with PlcSimulator(port=0, registers=45) as sim:  # a PLC with registers 0-44 only
        opts = PlcOptions("127.0.0.1", sim.port)
        writer = PlcWriter(ModbusLink(opts), opts, Health())
        status = {}
        source = ScriptedCamera(rendered, {35: lambda: wait_until(lambda: writer.stats.writes >= 10, "blocks")})
        source.hooks[36] = lambda: status.setdefault("text", writer.status())
        run_loop(source, [writer])
        blocks = [decode_block(w.values, WordOrder.ABCD) for w in sim.writes(0)]
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and "registers 100-219 (40101-40220)" in errors[0] and "only registers 0-44" in errors[0]
    assert "PLC ok" in status["text"] and "queue not written: exception 2" in status["text"]
    # The block kept coming (how many poses made it depends on the machine's load: latest wins).
    assert writer.stats.queue_writes == 0 and len(blocks) >= 10 and max(b["seq"] for b in blocks) >= 1
    assert blocks[-1]["status"] & 1 == 0


def test_cli_run_against_plc_sim_acting_as_the_arm(tmp_path):
    """The real CLI on both sides: `tracker plc-sim --arm-every` takes parts, `tracker run --plc` echoes them."""
    scene_dir = tmp_path / "scene"
    pattern = write_scene(queue_scene(3, n_frames=60), scene_dir)
    port = free_port()
    sim = start_sim_process(port, "--arm-every", "250", "--word-order", "CDAB")
    try:
        poses_path = tmp_path / "poses.jsonl"
        run = subprocess.run([TRACKER, "run", "--source", str(pattern), "--calibration",
                              str(scene_dir / "calibration.yaml"), "--fps", "30", "--realtime", "--quiet", "--plc",
                              f"127.0.0.1:{port}", "--plc-word-order", "CDAB", "--poses", str(poses_path)],
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stderr
    finally:
        out, err = stop_process(sim)
    took = [int(m) for m in re.findall(r"arm: took part (\d+) at", err)]
    assert len(took) >= 2 and len(set(took)) == len(took), err  # each part taken once
    assert "no echo" not in err
    ids = {o["id"] for line in read_poses(poses_path) for o in line["objects"]}
    assert set(took) <= ids
    assert re.search(rf"the arm took {len(took)} parts", out)


def test_the_demo_shows_the_handshake(capsys):
    from tracker.cli import main
    assert main(["run", "--max-frames", "75", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "its arm takes the first part of the queue every 1 s" in err
    m = re.search(r"plc-sim arm: took part (\d+) at x -?\d+\.\d mm y -?\d+\.\d mm \(queue_seq \d+\); "
                  r"echo after \d+ ms", err)
    assert m, err
    assert "no echo" not in err


def test_a_part_hidden_under_an_arm_stays_listed_with_its_age(tmp_path):
    """Part A is covered for 12 frames (0.4 s; frames rendered without it): the queue keeps its id, as
    predicted (measured 0) with age_frames counting, and it is measured again under the same id."""
    import dataclasses

    scene = queue_scene(2, n_frames=70, vx_mm_s=300.0, vy_mm_s=0.0)
    hidden = range(40, 52)
    b = scene.parts[1]
    with_both, only_b = Rendered(scene), Rendered(dataclasses.replace(scene, parts=(b,)))
    with_both.frames = [only_b.frames[i] if i in hidden else f for i, f in enumerate(with_both.frames)]
    wo = WordOrder.ABCD
    writer, sim, port = open_writer("client", wo, Health())
    source = ScriptedCamera(with_both)
    seen: dict = {}

    def read_at(k: int, key: str) -> None:
        want = ms_u32(source.arrival_ns[k - 1])
        wait_until(lambda: decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)["t_capture_ms"] == want,
                   f"the queue of frame {k - 1}")
        seen[key] = {int(e["id"]): e for e in read_queue_mbpoll(port, wo)[1]["entries"]}

    source.hooks = {39: lambda: read_at(39, "before"), 46: lambda: read_at(46, "hidden"),
                    60: lambda: read_at(60, "after")}
    poses = tmp_path / "poses.jsonl"
    run_loop(source, [PoseSink(str(poses)), writer])
    assert len(seen["before"]) == 2 and all(e["measured"] == 1 for e in seen["before"].values())
    hidden_entries = [e for e in seen["hidden"].values() if e["measured"] == 0]
    assert len(seen["hidden"]) == 2 and len(hidden_entries) == 1
    assert hidden_entries[0]["age_frames"] == 46 - hidden.start  # frames 40-45 without a measurement
    assert set(seen["after"]) == set(seen["before"]), "the same two ids after the arm has passed"
    assert all(e["measured"] == 1 and e["age_frames"] == 0 for e in seen["after"].values())
    assert len({o["id"] for line in read_poses(poses) for o in line["objects"]}) == 2


def test_touching_parts_reach_the_plc_as_two_entries_flagged_not_pickable(tmp_path):
    """Two parts touching at a corner (tests/test_touching.py): mbpoll reads two entries, each at its own
    part's true centre, each with flags bit 0 (not pickable) set."""
    from test_touching import _scene, _touching_at_a_corner

    from tracker.synthetic import Renderer

    scene = _scene(_touching_at_a_corner())
    truth = Renderer(scene).render(30)[1]
    rendered = Rendered(scene)
    wo = WordOrder.ABCD
    writer, sim, port = open_writer("client", wo, Health())
    source = ScriptedCamera(rendered)
    seen: dict = {}

    def read_at(k: int) -> None:
        want = ms_u32(source.arrival_ns[k - 1])
        wait_until(lambda: decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)["t_capture_ms"] == want,
                   f"the queue of frame {k - 1}")
        seen["queue"] = read_queue_mbpoll(port, wo)[1]

    source.hooks = {31: lambda: read_at(31)}
    run_loop(source, [writer])
    entries = seen["queue"]["entries"]
    assert len(entries) == 2
    for e in entries:
        d = min(math.dist((e["x_mm"], e["y_mm"]), (t["x_mm"], t["y_mm"])) for t in truth["objects"])
        assert d < 0.5, e
        assert e["flags"] & 1 == 1, e


class _LastIds:
    """A sink keeping the ids of the last frame handed to the sinks (what the pose stream reports)."""

    def __init__(self) -> None:
        self.ids: list[int] = []

    def submit(self, frame, result) -> None:
        self.ids = [o.id for o in result.objects]

    def status(self) -> str:
        return ""

    def close(self) -> None:
        pass


def test_a_taken_id_left_from_an_earlier_run_never_gets_a_part_picked_twice_and_exit_empties_the_queue():
    # Track ids start at 1 again in every run. A PLC still holding taken_id 1 from the run before would
    # write 1 again for this run's part 1: no change on the wire, and the echo, already 1, reads as
    # acted on; the part stayed listed and the arm would pick it twice. So it is not offered until the
    # PLC writes another taken_id.
    wo = WordOrder.ABCD
    health = Health()
    sim = PlcSimulator(port=0, word_order=wo).start()
    sim.store(TAKEN.address, encode_u32(1, wo))
    opts = PlcOptions("127.0.0.1", sim.port, word_order=wo)
    writer = PlcWriter(ModbusLink(opts), opts, health, owned=(sim,))
    source = ScriptedCamera(Rendered(queue_scene(3)))
    last = _LastIds()
    seen = {}

    def queue_of(k: int) -> dict:
        wait_until(lambda: decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)["t_capture_ms"]
                   == ms_u32(source.arrival_ns[k]), f"the queue of frame {k}")
        return decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)

    def take_another(k: int) -> None:
        queue = queue_of(k - 1)
        assert 1 in last.ids and queue["queue_count"] >= 1, "part 1 is tracked here, another listed"
        listed = [int(e["id"]) for e in queue["entries"]]
        assert 1 not in listed and queue["taken_echo"] == 1
        sim.store(TAKEN.address, encode_u32(listed[0], wo))  # the PLC takes another part
        wait_until(lambda: decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)["taken_echo"] == listed[0],
                   "the echo")
        seen["after"] = [int(e["id"]) for e in decode_queue(sim.read(QUEUE_START, QUEUE_WORDS), wo)["entries"]]
        seen["ids"] = list(last.ids)

    source.hooks = {30: lambda: take_another(30)}
    run_loop(source, [last, writer], health)
    queues = [decode_queue(w.values, wo) for w in sim.writes(QUEUE_START)]
    before = [q for q in queues if q["taken_echo"] == 1 and q["queue_count"]]
    assert before and all(1 not in [e["id"] for e in q["entries"]] for q in before)
    # Once the PLC has written another taken_id, part 1 (still in view) is offered like any other.
    assert 1 in seen["ids"] and 1 in seen["after"], seen
    # At exit the queue is written empty (a PLC committing then would wait for an echo in vain) and the
    # block says no part: count 0, running cleared.
    assert queues[-1]["queue_count"] == 0 and queues[-1]["in_view"] == 0 and queues[-1]["entries"] == []
    last_block = decode_block(sim.writes(0)[-1].values, wo)
    assert last_block["count"] == 0 and last_block["status"] & 1 == 0


def test_a_stale_taken_id_is_read_before_the_first_queue_offers_anything():
    # Part 1 in view when the writer first reaches the PLC: the stale id must be known before that first
    # queue is built, or the queue lists part 1 with its echo already 1 (found by a review: it did).
    wo = WordOrder.ABCD
    sim = PlcSimulator(port=0, word_order=wo).start()
    sim.store(TAKEN.address, encode_u32(1, wo))
    opts = PlcOptions("127.0.0.1", sim.port, word_order=wo)
    writer = PlcWriter(ModbusLink(opts), opts, Health(), owned=(sim,))
    corners = np.array([[-40.0, -25.0], [40.0, -25.0], [40.0, 25.0], [-40.0, 25.0]])
    part = TrackedObject(1, 0.0, 0.0, 0.0, 80.0, 50.0, corners, 300.0, 0.0, True)
    writer.submit(Frame(0, 0, np.zeros((4, 4), np.uint8), time.monotonic_ns()), FrameResult(0, 0, (part,)))
    try:
        wait_until(lambda: sim.writes(QUEUE_START), "the first queue")
        first = decode_queue(sim.writes(QUEUE_START)[0].values, wo)
        block = decode_block(sim.writes(0)[0].values, wo)
    finally:
        writer.close()
    assert first["taken_echo"] == 1 and first["queue_count"] == 0, first
    assert block["count"] == 0 and block["id"] == 0 and block["seq"] == 0, "part 1 is not reported as next"


def test_a_pose_still_pending_at_exit_reaches_the_block_before_the_final_status():
    # A pose submitted just before the writer closes is written as any other, then the final status
    # (queue empty, count 0, running cleared) keeps its fields: written only in that final status, its
    # fields never reached the block (the e2e test read the pose of two frames before, found by CI).
    wo = WordOrder.ABCD
    sim = PlcSimulator(port=0, word_order=wo).start()
    opts = PlcOptions("127.0.0.1", sim.port, word_order=wo)
    writer = PlcWriter(ModbusLink(opts), opts, Health(), owned=(sim,))
    corners = np.array([[-40.0, -25.0], [40.0, -25.0], [40.0, 25.0], [-40.0, 25.0]])
    for k in range(3):
        part = TrackedObject(1, 10.0 * k, 0.0, 0.0, 80.0, 50.0, corners, 300.0, 0.0, True)
        writer.submit(Frame(k, k, np.zeros((4, 4), np.uint8), time.monotonic_ns()), FrameResult(k, k, (part,)))
    writer.close()  # at once: the last pose is most likely still pending
    blocks = [decode_block(w.values, wo) for w in sim.writes(0)]
    assert blocks[-1]["x_mm"] == 20.0 and blocks[-1]["count"] == 0 and blocks[-1]["status"] & 1 == 0
    assert any(b["x_mm"] == 20.0 and b["count"] == 1 and b["status"] & 1 for b in blocks[:-1])
