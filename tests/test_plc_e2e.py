"""End to end: the real CLI writes to a real Modbus TCP server; mbpoll (an independent reader) checks it."""

from __future__ import annotations

import re
import signal
import socket
import subprocess

import numpy as np
import pytest
from plc_support import (
    DEADLINE_S,
    TRACKER,
    Rendered,
    ScriptedCamera,
    free_port,
    mbpoll,
    port_open,
    run_loop,
    small_scene,
    start_sim_process,
    stop_process,
    wait_until,
)

from plc.encode import WordOrder, decode_block, decode_f32
from plc.link import ModbusLink
from plc.options import PlcOptions
from plc.sim import PlcSimulator
from plc.sink import open_plc_sink
from plc.writer import PlcWriter
from tracker.cli import main
from tracker.cli_synth import write_scene
from tracker.health import Health
from tracker.pose_sink import PoseSink
from tracker.poses import read_poses

FLOATS = ("x_mm", "y_mm", "angle_deg", "vx_mm_s", "vy_mm_s", "length_mm", "width_mm")


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("plc_scene")
    pattern = write_scene(small_scene(100), out)
    return str(pattern), str(out / "calibration.yaml")


@pytest.fixture(scope="module")
def rendered():
    return Rendered(small_scene(100))


def expected_floats(obj: dict) -> list[float]:
    return [obj[k] for k in FLOATS] + [v for xy in obj["corners_mm"] for v in xy]


def last_pose(lines: list[dict]) -> tuple[dict, dict]:
    """The last line with objects and its reported object (the oldest track)."""
    line = [p for p in lines if p["objects"]][-1]
    return line, min(line["objects"], key=lambda o: o["id"])


@pytest.mark.parametrize(("order", "max_frames"), [("ABCD", 60), ("CDAB", None)])
def test_cli_run_to_plc_sim_read_back_with_mbpoll(scene_dir, tmp_path, order, max_frames):
    pattern, calib = scene_dir
    port = free_port()
    sim = start_sim_process(port, "--word-order", order)
    try:
        poses_path = tmp_path / "poses.jsonl"
        cmd = [TRACKER, "run", "--source", pattern, "--calibration", calib, "--fps", "60", "--quiet",
               "--plc", f"127.0.0.1:{port}", "--plc-word-order", order, "--poses", str(poses_path)]
        if max_frames:
            cmd += ["--max-frames", str(max_frames)]
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stderr
        assert run.stderr.count("connected (unit 1, base 0, word order " + order) == 1
        lines = read_poses(poses_path)
        assert len(lines) == (max_frames or 100)
        line, obj = last_pose(lines)

        big = order == "ABCD"
        floats = mbpoll(port, 12, 15, "4:float", big_endian=big)
        raw = mbpoll(port, 0, 45, "4:hex", big_endian=big)
        words = [int(raw[i], 16) for i in range(45)]
        ints = mbpoll(port, 4, 4, "4:int", big_endian=big)
        want = np.array(expected_floats(obj), dtype=np.float32)
        # mbpoll prints 6 significant digits ...
        got = np.array([float(floats[12 + 2 * i]) for i in range(15)])
        np.testing.assert_allclose(got, want, rtol=6e-6, atol=1e-12)
        # ... the raw words carry the float32 exactly, in the configured word order.
        wo = WordOrder(order)
        exact = [decode_f32(words[12 + 2 * i:14 + 2 * i], wo) for i in range(15)]
        assert exact == [float(v) for v in want]
        other = WordOrder.CDAB if big else WordOrder.ABCD
        assert decode_f32(words[12:14], other) != exact[0]  # the word order really matters

        block = decode_block(words, wo)
        assert int(ints[10]) == block["id"] == obj["id"]
        assert block["count"] == 0  # at exit no part is offered (the queue empty); the fields kept
        assert block["measured"] == int(obj["measured"])
        seq = int(ints[4])
        assert seq == block["seq"] and 1 <= seq <= sum(bool(p["objects"]) for p in lines)
        assert block["status"] & 1 == 0, "the final status clears the running bit"
        assert block["status"] & 0b110 == 0b110 and block["fault"] == 0
        assert block["t_write_ms"] >= block["t_capture_ms"]
    finally:
        out, err = stop_process(sim)
    assert sim.returncode == 0, err
    assert re.search(r"plc-sim stopped after (\d+) writes", out)


def test_seq_counts_poses_and_heartbeat_advances(rendered, tmp_path):
    with PlcSimulator(port=0) as sim:
        opts = PlcOptions("127.0.0.1", sim.port)
        writer = PlcWriter(ModbusLink(opts), opts, Health())
        # Before any part is in view the heartbeat must already move: hold the camera until it did.
        hooks = {5: lambda: wait_until(lambda: len(sim.writes(0)) >= 3, "heartbeat writes without parts")}
        poses = tmp_path / "poses.jsonl"
        summary = run_loop(ScriptedCamera(rendered, hooks), [PoseSink(str(poses)), writer])
        blocks = [decode_block(w.values, WordOrder.ABCD) for w in sim.writes(0)]
    assert summary.frames == 100 and writer.stats.submitted == 100
    assert blocks[0]["seq"] == 0 and blocks[0]["count"] == 0 and blocks[0]["status"] & 1
    xs = {float(np.float32(o["x_mm"])) for p in read_poses(poses) for o in p["objects"]}
    for prev, cur in zip(blocks, blocks[1:], strict=False):
        assert cur["heartbeat"] == (prev["heartbeat"] + 1) & 0xFFFF
        step = cur["seq"] - prev["seq"]
        assert step in (0, 1)
        new_pose = (cur["t_capture_ms"], cur["x_mm"]) != (prev["t_capture_ms"], prev["x_mm"])
        assert (step == 1) == new_pose, (prev, cur)
        if step:
            assert cur["x_mm"] in xs and cur["count"] >= 1
    assert blocks[-1]["seq"] == writer.stats.poses_written >= 1
    assert blocks[-1]["status"] & 1 == 0


def test_heartbeat_without_any_pose():
    with PlcSimulator(port=0) as sim:
        opts = PlcOptions("127.0.0.1", sim.port)
        writer = PlcWriter(ModbusLink(opts), opts, Health())
        try:
            wait_until(lambda: len(sim.writes(0)) >= 4, "four heartbeat writes")
            blocks = [decode_block(w.values, WordOrder.ABCD) for w in sim.writes(0)[:4]]
            assert writer.status().startswith("PLC ok") and "seq 0" in writer.status()
            assert writer.link._client.socket.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)
        finally:
            writer.close()
    assert [b["heartbeat"] for b in blocks] == [1, 2, 3, 4]
    assert {(b["seq"], b["count"], b["status"] & 1) for b in blocks} == {(0, 0, 1)}


def test_demo_runs_against_the_embedded_simulator(capsys):
    assert main(["run", "--max-frames", "3", "--quiet"]) == 0
    err = capsys.readouterr().err
    m = re.search(r"embedded PLC simulator on 127\.0\.0\.1:(\d+)", err)
    assert m, err
    assert "connected (unit 1" in err
    assert not port_open(int(m.group(1))), "the embedded simulator stops with the run"


def test_server_mode_serves_the_map_for_the_arm(rendered):
    port = free_port()
    args = type("Args", (), dict(no_plc=False, plc=f"127.0.0.1:{port}", plc_mode="server", plc_unit=1,
                                 plc_base=10, plc_word_order="CDAB"))()
    health = Health()
    sink = open_plc_sink(args, health, demo=False)
    source = ScriptedCamera(rendered)
    seen: dict = {}

    def poll_as_the_arm():
        newest = source.arrival_ns[-1] // 1_000_000 & 0xFFFFFFFF
        def current():
            seen["words"] = [int(v, 16) for v in mbpoll(port, 10, 45, "4:hex", big_endian=False).values()]
            return decode_block(seen["words"], WordOrder.CDAB)["t_capture_ms"] == newest
        wait_until(current, "the served map to hold the newest pose", DEADLINE_S)

    source.hooks = {50: poll_as_the_arm}
    summary = run_loop(source, [sink], health)
    assert summary.frames == 100
    block = decode_block(seen["words"], WordOrder.CDAB)
    assert block["status"] & 1 and block["count"] == 1 and block["seq"] >= 1
    assert not port_open(port), "the server stops with the run"


def test_sigterm_writes_a_final_status_with_running_cleared():
    with PlcSimulator(port=0) as sim:
        # The demo source is long enough (240 frames) to be stopped in the middle.
        proc = subprocess.Popen([TRACKER, "run", "--quiet", "--plc", f"127.0.0.1:{sim.port}"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            wait_until(lambda: decode_block(sim.read(), WordOrder.ABCD)["seq"] >= 1 or proc.poll() is not None,
                       "the first pose from the tracker", 30)
            assert decode_block(sim.read(), WordOrder.ABCD)["status"] & 1, "running while it runs"
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=DEADLINE_S)
        finally:
            if proc.poll() is None:
                proc.kill()
        block = decode_block(sim.read(), WordOrder.ABCD)
    assert proc.returncode == 0, err
    assert "stopped by signal" in out
    assert block["status"] & 1 == 0 and block["heartbeat"] >= 2
