"""Settings of the PLC link, with their defaults, in one typed place."""

from __future__ import annotations

from dataclasses import dataclass

from plc.encode import WordOrder
from plc.registers import MAX_BASE
from tracker.errors import BadInput

DEFAULT_SIM_HOST = "127.0.0.1"
DEFAULT_SIM_PORT = 5020


@dataclass(frozen=True)
class PlcOptions:
    host: str
    port: int
    unit: int = 1
    base: int = 0
    word_order: WordOrder = WordOrder.ABCD
    # Write at least this often without new poses: the contract's heartbeat is "at least every
    # 100 ms"; half of it leaves room for a slow write.
    heartbeat_s: float = 0.05
    # The queue (100-219) is rewritten at least this often without changes: the contract says 100 ms,
    # this leaves room for the thread's wake-up and a slow write.
    queue_period_s: float = 0.08
    # taken_id (290-291) is read this often: the echo is due within 100 ms of the PLC's write, and one
    # poll period plus one write must fit in that.
    taken_poll_s: float = 0.03
    # Parts slower than this say nothing about the belt's direction (pick order, plc.queue).
    min_belt_speed_mm_s: float = 5.0
    # Connect and response timeout of one request. A PLC slower than this is treated as lost.
    timeout_s: float = 1.0
    # Reconnect back-off after any failure: first wait, doubling up to the cap. The cap keeps the
    # promise "reconnected within 2 s of the PLC coming back" (one wait plus one connect and write).
    backoff_first_s: float = 0.1
    backoff_max_s: float = 1.5

    def __post_init__(self) -> None:
        if not self.host:
            raise BadInput("--plc: expected HOST:PORT, got an empty host")
        if not 1 <= self.port <= 65535:
            raise BadInput(f"--plc: expected a port 1-65535, got {self.port}")
        if not 0 <= self.unit <= 255:
            raise BadInput(f"--plc-unit: expected a Modbus unit id 0-255, got {self.unit}")
        if not 0 <= self.base <= MAX_BASE:
            raise BadInput(f"--plc-base: expected 0-{MAX_BASE} (registers base+0 to base+299 must fit "
                           f"in the 16-bit address space), got {self.base}")
        if not (0 < self.queue_period_s <= 0.1 and 0 < self.taken_poll_s <= 0.1 and self.min_belt_speed_mm_s > 0):
            raise ValueError(f"PLC queue timing: expected 0 < queue period, taken poll <= 0.1 s, belt speed > 0; got "
                             f"{self.queue_period_s}, {self.taken_poll_s}, {self.min_belt_speed_mm_s}")
        if not (0 < self.heartbeat_s <= 0.1 and self.timeout_s > 0 and 0 < self.backoff_first_s <= self.backoff_max_s):
            raise ValueError(f"PLC timing: expected 0 < heartbeat <= 0.1 s, timeout > 0, 0 < first back-off <= cap; "
                             f"got {self.heartbeat_s}, {self.timeout_s}, {self.backoff_first_s}, {self.backoff_max_s}")

    @property
    def endpoint(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


def parse_endpoint(text: str, option: str = "--plc") -> tuple[str, int]:
    """``HOST:PORT`` (``[v6addr]:PORT`` for IPv6) -> (host, port); BadInput naming the option otherwise."""
    host, sep, port_text = text.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not sep or not host or not port_text:
        raise BadInput(f"{option}: expected HOST:PORT (e.g. 192.168.0.10:502), got {text!r}")
    if ":" in host and not text.startswith("["):
        raise BadInput(f"{option}: write an IPv6 address in brackets, e.g. [::1]:502, got {text!r}")
    try:
        port = int(port_text)
    except ValueError:
        raise BadInput(f"{option}: expected a numeric port in HOST:PORT, got {text!r}") from None
    if not 1 <= port <= 65535:
        raise BadInput(f"{option}: expected a port 1-65535, got {port}")
    return host, port


def backoff_delays(first_s: float, max_s: float):
    """first, 2*first, 4*first, ... capped at max_s, forever."""
    delay = first_s
    while True:
        yield delay
        delay = min(delay * 2, max_s)
