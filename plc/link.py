"""The two ways a register block reaches the arm: a Modbus TCP client writing into the PLC
(``ModbusLink``), or the tracker's own server's datastore that the arm polls (``DatastoreLink``).

pymodbus's own reconnect and retries are disabled: the writer owns the reconnect loop, so
state changes are logged once and a dead PLC never blocks more than one request timeout.
"""

from __future__ import annotations

import socket
from typing import Protocol

from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from plc.options import PlcOptions

# Modbus exception codes (Modbus Application Protocol v1.1b3, section 7).
EXCEPTION_NAMES = {
    1: "illegal function", 2: "illegal data address", 3: "illegal data value", 4: "server device failure",
    5: "acknowledge", 6: "server device busy", 8: "memory parity error",
    10: "gateway path unavailable", 11: "gateway target device failed to respond",
}


class LinkDown(Exception):
    """No connection, or it broke (refused, reset, timeout): reconnect."""


class PlcRejected(Exception):
    """The PLC answered with a Modbus exception response: the connection is fine, the request is not."""

    def __init__(self, code: int, first: int, last: int, unit: int, what: str = "write") -> None:
        self.code = code
        name = EXCEPTION_NAMES.get(code, "unknown exception")
        super().__init__(f"exception {code} ({name}) to the {what} of registers {first}-{last} "
                         f"({40001 + first}-{40001 + last}) on unit {unit}")


class Link(Protocol):
    name: str

    @property
    def connected(self) -> bool: ...

    def connect(self) -> None: ...

    def write(self, address: int, registers: list[int]) -> None: ...

    def read(self, address: int, count: int) -> list[int]: ...

    def close(self) -> None: ...


class ModbusLink:
    def __init__(self, options: PlcOptions) -> None:
        self.options = options
        self.name = options.endpoint
        self._client = ModbusTcpClient(options.host, port=options.port, timeout=options.timeout_s, retries=0,
                                       reconnect_delay=0, reconnect_delay_max=0, name="plc")

    @property
    def connected(self) -> bool:
        return self._client.connected

    def connect(self) -> None:
        try:
            # create_connection with the request timeout: an unreachable host costs at most that long.
            sock = socket.create_connection((self.options.host, self.options.port), timeout=self.options.timeout_s)
        except OSError as exc:
            raise LinkDown(_reason(exc)) from None
        # One small request per pose: send it now, do not wait to coalesce (Nagle).
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client.close()
        self._client.socket = sock

    def write(self, address: int, registers: list[int]) -> None:
        if not self._client.connected:
            # pymodbus would connect by itself inside the request; the writer decides when to reconnect.
            raise LinkDown("not connected")
        try:
            response = self._client.write_registers(address, registers, device_id=self.options.unit)
        except Exception as exc:  # noqa: BLE001 - whatever a garbled answer makes pymodbus raise: reconnect
            self.close()
            raise LinkDown(self._failure(exc)) from None
        if response.isError():
            raise PlcRejected(getattr(response, "exception_code", 0), address, address + len(registers) - 1,
                              self.options.unit)

    def read(self, address: int, count: int) -> list[int]:
        """Holding registers the PLC owns (taken_id), with the same failure handling as ``write``."""
        if not self._client.connected:
            raise LinkDown("not connected")
        try:
            response = self._client.read_holding_registers(address, count=count, device_id=self.options.unit)
        except Exception as exc:  # noqa: BLE001 - as in write()
            self.close()
            raise LinkDown(self._failure(exc)) from None
        if response.isError():
            raise PlcRejected(getattr(response, "exception_code", 0), address, address + count - 1,
                              self.options.unit, "read")
        if len(response.registers) != count:
            self.close()
            raise LinkDown(f"expected {count} registers in the answer, got {len(response.registers)}")
        return list(response.registers)

    def _failure(self, exc: Exception) -> str:
        if isinstance(exc, OSError):
            return _reason(exc)
        if isinstance(exc, ModbusException):
            # pymodbus drops answers it cannot use (garbage, another transaction id) and then times out.
            return (f"no valid answer within {self.options.timeout_s:g} s" if "No response" in str(exc)
                    else "connection closed by the PLC")
        return f"unusable answer ({type(exc).__name__})"

    def close(self) -> None:
        self._client.close()


class DatastoreLink:
    """Server mode: the block goes straight into the embedded server's holding registers."""

    def __init__(self, simulator) -> None:
        self._sim = simulator
        self.name = f"server {simulator.host}:{simulator.port}"

    @property
    def connected(self) -> bool:
        return self._sim.running

    def connect(self) -> None:
        if not self._sim.running:
            raise LinkDown("the embedded server is not running")

    def write(self, address: int, registers: list[int]) -> None:
        self._sim.write(address, registers)

    def read(self, address: int, count: int) -> list[int]:
        return self._sim.read(address, count)

    def close(self) -> None:
        pass


def _reason(exc: OSError) -> str:
    if isinstance(exc, socket.timeout | TimeoutError):
        return "timed out"
    if isinstance(exc, socket.gaierror):
        return f"cannot resolve the host ({exc.strerror})"
    return exc.strerror or str(exc)
