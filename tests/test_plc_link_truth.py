"""The PLC link tells the truth (issue 13): "ok" only after an acknowledged write; PLCs that accept TCP but
never complete a write are a fault after the request timeout; back-off after every kind of failure; a real
restart on the same port is written to again within 2 s; the final block after a fatal error."""

from __future__ import annotations

import logging
import signal
import socket
import struct
import threading
import time

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

from plc.encode import WordOrder, decode_block
from plc.link import ModbusLink
from plc.options import PlcOptions
from plc.sim import PlcSimulator
from plc.writer import PlcWriter
from tracker.cli import main as main_run
from tracker.health import FAULT_CAMERA_LOST, Health

TIMEOUT_S = 0.3


class BadPlc:
    """A real TCP listener on 127.0.0.1 that speaks Modbus badly, in one of these ways."""

    MODES = ("silent", "garbage", "wrong_tid", "late", "close")

    def __init__(self, mode: str, late_s: float = TIMEOUT_S * 2) -> None:
        self.mode = mode
        self.late_s = late_s
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.accepted = 0
        self.requests = 0
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.accepted += 1
            threading.Thread(target=self._handle, args=(conn,), daemon=True).start()

    def _handle(self, conn: socket.socket) -> None:
        with conn:
            if self.mode == "close":
                return
            while True:
                head = conn.recv(7, socket.MSG_WAITALL)
                if len(head) < 7:
                    return
                tid, _, length, unit = struct.unpack(">HHHB", head)
                pdu = conn.recv(length - 1, socket.MSG_WAITALL)
                self.requests += 1
                if self.mode == "silent":
                    continue
                if self.mode == "garbage":
                    conn.sendall(b"\xde\xad\xbe\xef\x00\x01\xff" * 3)
                    continue
                if pdu[0] == 3:
                    qty = struct.unpack(">H", pdu[3:5])[0]
                    reply = struct.pack(f">BB{qty}H", 3, 2 * qty, *[0] * qty)
                else:
                    reply = pdu[:5]  # function 16: echo address and quantity
                if self.mode == "wrong_tid":
                    tid = (tid + 7) & 0xFFFF
                if self.mode == "late" and threading.Event().wait(self.late_s):
                    pass
                try:
                    conn.sendall(struct.pack(">HHHB", tid, 0, len(reply) + 1, unit) + reply)
                except OSError:
                    return

    def close(self) -> None:
        self.sock.close()


@pytest.mark.parametrize("mode", BadPlc.MODES)
def test_a_plc_that_never_completes_a_write_is_never_ok(mode, caplog):
    caplog.set_level(logging.INFO, logger="plc.writer")
    plc = BadPlc(mode)
    opts = PlcOptions("127.0.0.1", plc.port, timeout_s=TIMEOUT_S, backoff_max_s=0.4)
    writer = PlcWriter(ModbusLink(opts), opts, Health())
    statuses: set[str] = set()
    try:
        wait_until(lambda: plc.accepted >= 1, "the first connection")
        end = time.monotonic() + 4 * TIMEOUT_S + 1.0
        while time.monotonic() < end:  # sample the status line as the loop would, for a while
            statuses.add(writer.status().split(" ")[1])
            threading.Event().wait(0.005)
        wait_until(lambda: writer.status() == "PLC lost", "the link to be reported lost")
    finally:
        writer.close()
        plc.close()
    assert "ok" not in statuses and writer.stats.writes == 0
    assert statuses <= {"connecting", "lost"}
    lines = [r.getMessage() for r in caplog.records if r.name == "plc.writer" and r.levelno >= logging.WARNING]
    assert len(lines) == 1 and "accepts connections but does not answer writes" in lines[0], lines
    # Back-off after every failure: in ~2.2 s with waits 0.1, 0.2, 0.4, 0.4, ... (plus a timeout per try
    # where the PLC keeps quiet) a handful of connections, not hundreds.
    assert 2 <= plc.accepted <= 12, plc.accepted


def test_status_is_ok_only_after_the_first_acknowledged_write():
    with PlcSimulator(port=0, response_delay_s=0.3) as sim:
        opts = PlcOptions("127.0.0.1", sim.port)
        writer = PlcWriter(ModbusLink(opts), opts, Health())
        try:
            wait_until(lambda: writer.stats.connects >= 1, "the connection")
            before = writer.status() if writer.stats.writes == 0 else None
            wait_until(lambda: writer.stats.writes >= 1, "the first acknowledged write")
            after = writer.status()
        finally:
            writer.close()
    assert before in (None, "PLC connecting")  # None: the write was acknowledged before we looked
    assert after.startswith("PLC ok")


class RecordingLink(ModbusLink):
    """The real link, noting when each connect attempt was made and whether it worked."""

    def __init__(self, options: PlcOptions) -> None:
        super().__init__(options)
        self.attempts: list[tuple[float, bool]] = []

    def connect(self) -> None:
        try:
            super().connect()
        except Exception:
            self.attempts.append((time.monotonic(), False))
            raise
        self.attempts.append((time.monotonic(), True))


def test_real_restart_on_the_same_port_is_written_again_within_two_seconds(caplog):
    caplog.set_level(logging.INFO, logger="plc.writer")
    port = free_port()
    proc = start_sim_process(port)
    opts = PlcOptions("127.0.0.1", port)  # the default back-off: the README's promise
    link = RecordingLink(opts)
    writer = PlcWriter(link, opts, Health())
    procs = [proc]
    try:
        wait_until(lambda: writer.status().startswith("PLC ok"), "the first acknowledged write")
        stop_process(proc, signal.SIGKILL)
        wait_until(lambda: writer.state == "lost", "the writer to notice the loss")
        # Down long enough (as in the report: 4.2 s) for the back-off to reach its cap.
        wait_until(lambda: sum(not ok for _, ok in link.attempts) >= 6, "six failed connect attempts", 15)
        procs.append(start_sim_process(port))
        back = time.monotonic()
        writes = writer.stats.writes
        wait_until(lambda: writer.stats.writes > writes, "a write acknowledged by the restarted PLC")
        acked = time.monotonic()
    finally:
        writer.close()
        for p in procs:
            stop_process(p)
    after = [(t, ok) for t, ok in link.attempts if t >= back]
    assert after and after[0][1], "the first attempt after the restart connected"
    assert acked - back < 2.0, f"written again {acked - back:.2f} s after the PLC came back"
    assert len([r for r in caplog.records if "reconnected after" in r.getMessage()]) == 1
    assert len([r for r in caplog.records if "connection lost" in r.getMessage()]) == 1


def test_final_block_after_a_fatal_error_clears_running_and_sets_the_fault():
    rendered = Rendered(small_scene(30))
    with PlcSimulator(port=0) as sim:
        opts = PlcOptions("127.0.0.1", sim.port)
        health = Health()
        writer = PlcWriter(ModbusLink(opts), opts, health)

        def boom():
            wait_until(lambda: writer.stats.writes >= 2, "the writer running")
            raise RuntimeError("a damaged frame")

        with pytest.raises(RuntimeError, match="damaged frame"):
            run_loop(ScriptedCamera(rendered, {10: boom}), [writer], health)
        block = decode_block(sim.read(), WordOrder.ABCD)
    assert block["status"] & 1 == 0 and block["status"] & (1 << 15)
    assert block["fault"] == FAULT_CAMERA_LOST


def test_empty_plc_option_is_refused(capsys):
    assert main_run(["run", "--plc", "", "--max-frames", "1", "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--plc: expected HOST:PORT" in lines[0], lines


def test_server_mode_log_lines_name_the_tracker_server(caplog):
    import argparse

    from plc.sink import open_plc_sink
    caplog.set_level(logging.INFO)
    port = free_port()
    args = argparse.Namespace(no_plc=False, plc=f"127.0.0.1:{port}", plc_mode="server", plc_unit=1, plc_base=0,
                              plc_word_order="ABCD")
    writer = open_plc_sink(args, Health(), demo=False)
    sim = writer._owned[0]
    sim.log_period_s = 0.05
    try:
        wait_until(lambda: any("writes" in r.getMessage() for r in caplog.records if r.name == "plc.sim"),
                   "a server log line")
    finally:
        writer.close()
    lines = [r.getMessage() for r in caplog.records if r.name == "plc.sim"]
    assert lines and all(line.startswith(f"tracker's PLC server 127.0.0.1:{port}:") for line in lines), lines
    assert not any("plc-sim" in r.getMessage() for r in caplog.records)


def test_refused_writes_are_retried_at_the_heartbeat_rate_not_in_a_busy_loop():
    with PlcSimulator(port=0) as sim:
        opts = PlcOptions("127.0.0.1", sim.port, base=300)  # past the server's 300 registers
        writer = PlcWriter(ModbusLink(opts), opts, Health())
        try:
            wait_until(lambda: writer.stats.rejected >= 1, "the first refused write")
            first = writer.stats.rejected
            threading.Event().wait(1.0)  # a window to count in, not a wait for a server
            refused = writer.stats.rejected - first
        finally:
            writer.close()
    # One attempt per heartbeat (50 ms): about 20 in a second; a busy loop makes thousands.
    assert 5 <= refused <= 40, refused
    assert writer.stats.queue_writes == 0 and writer.stats.taken_polls == 0


class BrokenSink:
    """A sink whose close fails with an unexpected error (a device gone at exit)."""

    def submit(self, frame, result) -> None:
        pass

    def status(self) -> str:
        return ""

    def close(self) -> None:
        raise OSError(5, "Input/output error")


def test_a_sink_failing_at_close_does_not_keep_the_final_block_from_the_plc():
    rendered = Rendered(small_scene(20))
    with PlcSimulator(port=0) as sim:
        opts = PlcOptions("127.0.0.1", sim.port)
        writer = PlcWriter(ModbusLink(opts), opts, Health())
        with pytest.raises(OSError, match="Input/output error"):
            run_loop(ScriptedCamera(rendered), [BrokenSink(), writer])
        block = decode_block(sim.read(), WordOrder.ABCD)
    assert not writer._thread.is_alive()
    assert block["status"] & 1 == 0 and block["heartbeat"] >= 1


def test_cli_against_a_plc_that_closes_at_once_logs_one_line(capsys):
    plc = BadPlc("close")
    try:
        assert main_run(["run", "--max-frames", "45", "--quiet", "--plc", f"127.0.0.1:{plc.port}"]) == 0
    finally:
        plc.close()
    err = capsys.readouterr().err.strip().splitlines()
    plc_lines = [line for line in err if "PLC 127.0.0.1" in line]
    assert len(plc_lines) == 1 and "does not answer writes" in plc_lines[0], err
    assert len(err) <= 3, err  # that line, and at most the demo's own
    assert plc.accepted <= 10, plc.accepted  # 1.5 s of back-off, not hundreds of reconnects
