"""A stand-in PLC: a real Modbus TCP server (pymodbus) holding the register map.

``PlcSimulator(...).start()`` runs the asyncio server in a thread of its own, so tests, the
demo and ``--plc-mode server`` can use it in-process; ``tracker plc-sim`` runs it until
interrupted. It logs the writes it receives at a human rate (default once a second).
"""

from __future__ import annotations

import asyncio
import collections
import logging
import threading
import time
from dataclasses import dataclass

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from plc.encode import WordOrder, decode_block, decode_queue
from plc.options import DEFAULT_SIM_HOST, DEFAULT_SIM_PORT
from plc.registers import BLOCK_WORDS, QUEUE_WORDS, SERVER_REGISTERS
from tracker.errors import BadInput, TrackerError

log = logging.getLogger(__name__)

# Modbus function codes that write holding registers.
_WRITE_CODES = (6, 16)
START_TIMEOUT_S = 5.0
HISTORY_LEN = 10_000


class SimulatorError(TrackerError):
    """The simulator did not start."""


class CannotListen(SimulatorError, BadInput):
    """The address given cannot be listened on (in use, or not this machine's): bad input, exit 2, as
    the live view's --web address is."""

    exit_code = 2


@dataclass(frozen=True)
class Write:
    """One accepted write request, as received (for the log and the tests)."""

    t_ns: int  # monotonic time it was received
    address: int
    values: tuple[int, ...]


class PlcSimulator:
    def __init__(self, host: str = DEFAULT_SIM_HOST, port: int = DEFAULT_SIM_PORT,
                 registers: int = SERVER_REGISTERS, word_order: WordOrder = WordOrder.ABCD,
                 log_period_s: float = 1.0, response_delay_s: float = 0.0, label: str = "plc-sim") -> None:
        if registers < BLOCK_WORDS or registers > 0x10000:
            raise ValueError(f"simulator: expected {BLOCK_WORDS}-65536 registers, got {registers}")
        self.host = host
        self.port = port  # 0: any free port; the real one once started
        self.size = registers
        # Names the server in its log lines: "plc-sim" (a stand-in PLC) or the tracker's own server.
        self.label = label
        self.word_order = word_order
        self.log_period_s = log_period_s
        # Answer every request this late (to test a slow PLC).
        self.response_delay_s = response_delay_s
        self.history: collections.deque[Write] = collections.deque(maxlen=HISTORY_LEN)
        self.write_count = 0
        self.running = False
        self._registers: list[int] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_event: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: str | None = None
        self._cannot_listen = False
        self._thread: threading.Thread | None = None

    # ---- life cycle ----
    def start(self) -> PlcSimulator:
        self._thread = threading.Thread(target=self._thread_main, name="plc-sim", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S):
            raise SimulatorError(f"{self.label} on {self.host}:{self.port}: did not start in {START_TIMEOUT_S} s")
        if self._error:
            raise (CannotListen if self._cannot_listen else SimulatorError)(self._error)
        return self

    def stop(self) -> None:
        loop, event = self._loop, self._stop_event
        if loop is not None and event is not None and self.running:
            loop.call_soon_threadsafe(event.set)
        if self._thread is not None:
            self._thread.join(timeout=START_TIMEOUT_S)

    def __enter__(self) -> PlcSimulator:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ---- the datastore ----
    def read(self, address: int = 0, count: int = BLOCK_WORDS) -> list[int]:
        regs = self._require()
        self._check_range(address, count)
        return regs[address:address + count]  # one slice: never half of a write

    def write(self, address: int, values: list[int]) -> None:
        """Server mode: the tracker updates its own map (one slice assignment: atomic for readers)."""
        regs = self._require()
        self._check_range(address, len(values))
        regs[address:address + len(values)] = values
        self._record(address, values)

    def store(self, address: int, values: list[int]) -> None:
        """The PLC program's own write into its registers (the arm's taken_id): not a received write."""
        regs = self._require()
        self._check_range(address, len(values))
        regs[address:address + len(values)] = values

    def writes(self, address: int = 0) -> list[Write]:
        """The recorded writes that started at ``address`` (0: the blocks, 100: the queues)."""
        return [w for w in list(self.history) if w.address == address]

    def _require(self) -> list[int]:
        if self._registers is None:
            raise SimulatorError("PLC simulator: not started")
        return self._registers

    def _check_range(self, address: int, count: int) -> None:
        if address < 0 or address + count > self.size:
            raise ValueError(f"simulator: registers {address}-{address + count - 1} outside 0-{self.size - 1}")

    def _record(self, address: int, values) -> None:
        self.history.append(Write(time.monotonic_ns(), address, tuple(values)))
        self.write_count += 1

    # ---- the server thread ----
    def _thread_main(self) -> None:
        try:
            asyncio.run(self._serve())
        except Exception as exc:  # noqa: BLE001 - reported to start() as one line
            self._error = f"{self.label} on {self.host}:{self.port}: {exc}"
        finally:
            self.running = False
            self._ready.set()

    async def _action(self, function_code: int, _start: int, address: int, _count: int,
                      _registers: list[int], set_values) -> None:
        if self.response_delay_s:
            await asyncio.sleep(self.response_delay_s)
        if function_code in _WRITE_CODES and set_values is not None:
            self._record(address, set_values)
        return None

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop_event = asyncio.Event()
        device = SimDevice(id=0, simdata=[SimData(0, count=self.size, values=0, datatype=DataType.REGISTERS)],
                           action=self._action)
        server = ModbusTcpServer(device, address=(self.host, self.port))
        try:
            await server.serve_forever(background=True)
        except RuntimeError:
            self._cannot_listen = True
            self._error = (f"cannot listen on {self.host}:{self.port} (address in use, not an address of this "
                           f"machine, or a port below 1024 without the right to it)")
            return
        # id 0 = every unit id; "x" = the one shared block of registers.
        self._registers = server.context.devices[0].block["x"][2]
        self.port = server.transport.sockets[0].getsockname()[1]
        self.running = True
        self._ready.set()
        try:
            await self._log_until_stopped()
        finally:
            self.running = False
            await server.shutdown()

    async def _log_until_stopped(self) -> None:
        assert self._stop_event is not None
        seen = 0
        while True:
            try:
                await asyncio.wait_for(self._stop_event.wait(), self.log_period_s)
                return
            except TimeoutError:
                pass
            if self.write_count != seen:
                log.info("%s", self.describe_writes(self.write_count - seen))
                seen = self.write_count

    def describe_writes(self, n: int) -> str:
        """One line: how many writes, the newest block (0-44) and the newest queue (100-219) among them."""
        recent = list(self.history)[-max(1, min(n, 16)):]
        block = next((w for w in reversed(recent) if len(w.values) == BLOCK_WORDS), None)
        queue = next((w for w in reversed(recent) if len(w.values) == QUEUE_WORDS), None)
        parts = [f"{self.label}: {n} writes"]
        if block is not None:
            v = decode_block(block.values, self.word_order)
            parts.append(f"block (registers {block.address}-{block.address + BLOCK_WORDS - 1}): seq {v['seq']} "
                         f"count {v['count']} x {v['x_mm']:.1f} mm y {v['y_mm']:.1f} mm angle {v['angle_deg']:.1f} "
                         f"deg heartbeat {v['heartbeat']} status 0x{v['status']:04x} fault {v['fault']}")
        if queue is not None:
            q = decode_queue(queue.values, self.word_order)
            parts.append(f"queue (registers {queue.address}-{queue.address + QUEUE_WORDS - 1}): seq {q['queue_seq']} "
                         f"ids {[int(e['id']) for e in q['entries']]} in view {q['in_view']} "
                         f"echo {q['taken_echo']}")
        if block is None and queue is None:
            last = self.history[-1]
            parts.append(f"last: registers {last.address}-{last.address + len(last.values) - 1}")
        return "; ".join(parts)
