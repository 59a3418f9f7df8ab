"""A PLC that is absent, dies, answers late or refuses: the loop keeps processing every frame, the
writer logs each state change once and recovers; nothing crashes."""

from __future__ import annotations

import logging
import signal
import socket
import struct
import threading

import numpy as np
import pytest
from plc_support import (
    Rendered,
    ScriptedCamera,
    free_port,
    run_loop,
    small_scene,
    start_sim_process,
    stop_process,
    wait_until,
)

from plc.block import ms_u32
from plc.encode import WordOrder, decode_block
from plc.link import ModbusLink
from plc.options import PlcOptions
from plc.sim import PlcSimulator
from plc.writer import PlcWriter
from tracker.cli import main
from tracker.health import Health
from tracker.poses import FrameResult, TrackedObject
from tracker.sources import Frame

N = 100


@pytest.fixture(scope="module")
def rendered():
    return Rendered(small_scene(N))


def writer_for(port: int, **kw) -> PlcWriter:
    # A short back-off cap keeps the tests quick; the default (2 s) is checked in test_plc_encode.
    opts = PlcOptions("127.0.0.1", port, backoff_max_s=kw.pop("backoff_max_s", 0.4), **kw)
    return PlcWriter(ModbusLink(opts), opts, Health())


def read_block(port: int) -> dict:
    """Read registers 0-44 with a fresh client (as the arm would)."""
    link = ModbusLink(PlcOptions("127.0.0.1", port))
    link.connect()
    try:
        response = link._client.read_holding_registers(0, count=45, device_id=1)
        return decode_block(response.registers, WordOrder.ABCD)
    finally:
        link.close()


def messages(caplog, needle: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if needle in r.getMessage()]


def test_plc_absent_at_start_connects_when_it_appears(rendered, caplog):
    caplog.set_level(logging.INFO)
    port = free_port()
    writer = writer_for(port)
    sims: list[PlcSimulator] = []

    def plc_appears():
        # 30 frames processed with nobody listening: the loop did not wait for the PLC.
        assert writer.stats.submitted == 30 and writer.stats.writes == 0 and writer.state == "connecting"
        sims.append(PlcSimulator(port=port).start())
        wait_until(lambda: writer.stats.writes > 0, "the writer to connect and write")

    source = ScriptedCamera(rendered, {30: plc_appears})
    try:
        summary = run_loop(source, [writer])
        block = decode_block(sims[0].read(), WordOrder.ABCD)
    finally:
        for sim in sims:
            sim.stop()
    assert summary.frames == N and writer.stats.submitted == N
    assert len(messages(caplog, "not reachable")) == 1
    assert len(messages(caplog, "connected (unit 1")) == 1
    assert block["seq"] == writer.stats.poses_written >= 1
    assert block["status"] & 1 == 0  # final status written at close


def test_plc_killed_mid_run_and_restarted(rendered, caplog):
    caplog.set_level(logging.INFO)
    port = free_port()
    procs = [start_sim_process(port)]
    writer = writer_for(port)
    source = ScriptedCamera(rendered)
    seen: dict = {}

    def kill_plc():
        newest = ms_u32(source.arrival_ns[-1])
        wait_until(lambda: writer._builder.state.t_capture_ms == newest, "the newest pose to be written")
        seen["seq_before"] = writer._builder.state.seq
        stop_process(procs[0], signal.SIGKILL)
        wait_until(lambda: writer.state == "lost", "the writer to notice the PLC is gone")
        seen["submitted_at_loss"] = writer.stats.submitted

    def restart_plc():
        seen["writes_while_down"] = writer.stats.writes
        procs.append(start_sim_process(port))
        newest = ms_u32(source.arrival_ns[-1])
        wait_until(lambda: writer.stats.connects == 2, "the writer to reconnect")
        wait_until(lambda: read_block(port)["t_capture_ms"] == newest, "the newest pose on the restarted PLC")
        seen["after"] = read_block(port)

    source.hooks = {40: kill_plc, 60: restart_plc}
    try:
        summary = run_loop(source, [writer])
        final = read_block(port)
    finally:
        for proc in procs:
            stop_process(proc)
    assert summary.frames == N and writer.stats.submitted == N
    # Frames 40-59 went through the loop while the PLC was dead.
    assert seen["submitted_at_loss"] <= 41 and seen["writes_while_down"] >= 1
    # The first pose on the restarted PLC is the newest one, and seq continued (+1, not reset).
    assert seen["after"]["seq"] == seen["seq_before"] + 1
    assert seen["after"]["status"] & 1
    assert final["seq"] == writer.stats.poses_written and final["status"] & 1 == 0
    assert len(messages(caplog, "connection lost")) == 1
    assert len(messages(caplog, "reconnected after")) == 1
    assert writer.stats.losses == 1


def test_plc_answering_500_ms_late(rendered):
    with PlcSimulator(port=0, response_delay_s=0.5) as sim:
        writer = writer_for(sim.port)
        hooks = {50: lambda: wait_until(lambda: writer.stats.writes >= 2, "two slow writes")}
        summary = run_loop(ScriptedCamera(rendered, hooks), [writer])
        block = decode_block(sim.read(), WordOrder.ABCD)
    assert summary.frames == N and writer.stats.submitted == N
    # The loop handed over 100 poses while only a few writes could complete: it never waited for them.
    assert writer.stats.writes < 10 and writer.stats.replaced > N - 15
    assert writer.stats.losses == 0 and writer.stats.max_latency_ms >= 500
    assert block["seq"] == writer.stats.poses_written and block["status"] & 1 == 0


def test_plc_exception_responses_are_reported_once(rendered, caplog):
    caplog.set_level(logging.INFO)
    with PlcSimulator(port=0) as sim:
        # --plc-base past the server's 300 registers: every write is an illegal address.
        writer = writer_for(sim.port, base=300)
        hooks = {20: lambda: wait_until(lambda: writer.stats.rejected >= 3, "rejected writes")}
        source = ScriptedCamera(rendered, hooks)
        status = {}
        source.hooks[21] = lambda: status.setdefault("text", writer.status())
        summary = run_loop(source, [writer])
        accepted = sim.write_count
    assert summary.frames == N and writer.stats.submitted == N
    assert accepted == 0 and writer.stats.writes == 0 and writer.stats.rejected >= 3
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1
    assert "exception 2 (illegal data address)" in errors[0].getMessage()
    assert "registers 300-344 (40301-40345)" in errors[0].getMessage()
    assert status["text"] == "PLC rejected: exception 2 (illegal data address)"


def test_cli_exception_response_keeps_running(tmp_path, capsys):
    with PlcSimulator(port=0) as sim:
        poses = tmp_path / "p.jsonl"
        code = main(["run", "--max-frames", "20", "--quiet", "--plc", f"127.0.0.1:{sim.port}", "--plc-base", "280",
                     "--poses", str(poses)])
    err = capsys.readouterr().err
    assert code == 0
    assert err.count("illegal data address") == 1
    assert len(poses.read_text().splitlines()) == 20


def test_cli_unreachable_plc_is_not_fatal(capsys):
    port = free_port()
    assert main(["run", "--max-frames", "5", "--quiet", "--plc", f"127.0.0.1:{port}"]) == 0
    captured = capsys.readouterr()
    assert captured.err.count("not reachable (") == 1
    assert "5 frames" in captured.out


@pytest.mark.parametrize(("argv", "needle"), [
    (["--plc", "plc.local"], "--plc: expected HOST:PORT"),
    (["--plc", "127.0.0.1:99999"], "--plc: expected a port 1-65535, got 99999"),
    (["--plc", "127.0.0.1:502", "--plc-unit", "256"], "--plc-unit: expected a Modbus unit id 0-255, got 256"),
    (["--plc", "127.0.0.1:502", "--plc-base", "-5"], "--plc-base: expected 0-65236"),
])
def test_bad_plc_options_exit_2_with_one_line(argv, needle, capsys):
    assert main(["run", "--max-frames", "1", "--quiet", *argv]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracker: error: ") and needle in lines[0], lines


def test_submit_returns_while_the_plc_hangs():
    """A PLC that accepts the connection and never answers: the writer hangs in its request, and
    submit() (the loop's side) still only swaps the slot."""
    with socket.socket() as mute:
        mute.bind(("127.0.0.1", 0))
        mute.listen()
        writer = writer_for(mute.getsockname()[1], timeout_s=0.5)
        try:
            wait_until(lambda: writer.stats.connects >= 1, "the connection to the mute PLC")
            assert writer.status() == "PLC connecting", "ok only once a write is acknowledged"
            frame = Frame(0, 0, np.zeros((2, 2), np.uint8), 1)
            for _ in range(1000):
                writer.submit(frame, FrameResult(0, 0, ()))
            assert writer.stats.submitted == 1000 and writer.stats.replaced >= 998 and writer.stats.writes == 0
        finally:
            writer.close()
    # Never acknowledged: not a "loss" of a working link, and never "ok".
    assert writer.stats.writes == 0 and writer.stats.losses == 0 and writer.status() == "PLC closed"


class CrashOnFirstPose:
    """A minimal real Modbus TCP server (function 16 only) that drops the connection without an
    answer on the first block carrying a pose, as a PLC that dies in the middle of a request."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.crashed = False
        self.accepted: list[list[int]] = []
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._handle, args=(conn,), daemon=True).start()

    def _handle(self, conn: socket.socket) -> None:
        with conn:
            while True:
                head = conn.recv(7, socket.MSG_WAITALL)
                if len(head) < 7:
                    return
                tid, _, length, unit = struct.unpack(">HHHB", head)
                pdu = conn.recv(length - 1, socket.MSG_WAITALL)
                if pdu[0] == 3:  # read holding registers (taken_id): zeros
                    qty = struct.unpack(">H", pdu[3:5])[0]
                    conn.sendall(struct.pack(f">HHHBBB{qty}H", tid, 0, 3 + 2 * qty, unit, 3, 2 * qty, *[0] * qty))
                    continue
                _, address, qty, _ = struct.unpack(">BHHB", pdu[:6])
                regs = list(struct.unpack(f">{qty}H", pdu[6:6 + 2 * qty]))
                if regs[3] > 0 and not self.crashed:
                    self.crashed = True
                    return  # close without answering
                if address == 0:
                    self.accepted.append(regs)
                conn.sendall(struct.pack(">HHHBBHH", tid, 0, 6, unit, 16, address, qty))

    def close(self) -> None:
        self.sock.close()


def test_pose_in_flight_when_the_plc_dies_is_written_after_reconnect():
    server = CrashOnFirstPose()
    writer = writer_for(server.port, backoff_first_s=0.05)
    try:
        wait_until(lambda: len(server.accepted) >= 1, "a heartbeat write")
        corners = np.array([[0, 0], [80, 0], [80, 50], [0, 50]], dtype=float)
        obj = TrackedObject(7, 40.0, 25.0, 0.0, 80.0, 50.0, corners, 300.0, 0.0, True)
        writer.submit(Frame(0, 0, np.zeros((2, 2), np.uint8), 123_000_000), FrameResult(0, 0, (obj,)))
        wait_until(lambda: any(r[3] for r in server.accepted), "the pose to be written after the reconnect")
    finally:
        writer.close()
        server.close()
    assert server.crashed and writer.stats.losses == 1 and writer.stats.connects == 2
    block = decode_block(next(r for r in server.accepted if r[3]), WordOrder.ABCD)
    assert (block["seq"], block["id"], block["t_capture_ms"], block["x_mm"]) == (1, 7, 123, 40.0)


def test_last_pose_of_a_part_is_not_replaced_by_the_empty_frame_after_it():
    port = free_port()
    writer = writer_for(port)  # nobody listens yet: both frames wait in the slot
    corners = np.array([[0, 0], [80, 0], [80, 50], [0, 50]], dtype=float)
    part = TrackedObject(4, 40.0, 25.0, 0.0, 80.0, 50.0, corners, 300.0, 0.0, True)
    image = np.zeros((2, 2), np.uint8)
    writer.submit(Frame(0, 0, image, 10_000_000), FrameResult(0, 0, (part,)))
    writer.submit(Frame(1, 1, image, 20_000_000), FrameResult(1, 1, ()))
    with PlcSimulator(port=port) as sim:
        try:
            wait_until(lambda: len(sim.writes(0)) >= 2, "two writes")
        finally:
            writer.close()
        blocks = [decode_block(w.values, WordOrder.ABCD) for w in sim.writes(0)]
    first, second = blocks[0], blocks[1]
    assert (first["seq"], first["count"], first["id"], first["t_capture_ms"]) == (1, 1, 4, 10)
    assert (second["seq"], second["count"], second["id"], second["t_capture_ms"]) == (1, 0, 4, 10)
    assert blocks[-1]["count"] == 0
