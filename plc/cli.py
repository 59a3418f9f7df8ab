"""``tracker plc-sim`` (a stand-in PLC) and ``tracker plc map`` (the register map for the PLC programmer)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from plc.arm import Arm
from plc.encode import WordOrder
from plc.mapdoc import FORMATS, render
from plc.options import DEFAULT_SIM_HOST, DEFAULT_SIM_PORT
from plc.registers import MAX_BASE, SERVER_REGISTERS
from plc.sim import PlcSimulator
from tracker.errors import BadInput

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plc-sim", help="stand-in PLC: a Modbus TCP server holding the register map",
                       description=f"Serves holding registers 0-{SERVER_REGISTERS - 1} over Modbus TCP (any unit id) "
                       "until interrupted, "
                       "and logs the writes it receives once a second. Modbus has no authentication: keep it "
                       "on 127.0.0.1 or an isolated cell network.")
    p.add_argument("--host", default=DEFAULT_SIM_HOST, help=f"address to listen on (default {DEFAULT_SIM_HOST})")
    p.add_argument("--port", type=int, default=DEFAULT_SIM_PORT,
                   help=f"TCP port (default {DEFAULT_SIM_PORT}; 0: any free port, printed at start)")
    p.add_argument("--word-order", choices=[o.value for o in WordOrder], default=WordOrder.ABCD.value,
                   help="word order used to decode 32-bit values in the log (default ABCD)")
    p.add_argument("--arm-every", type=float, metavar="MS",
                   help="act as the arm too: every MS milliseconds take the first part of the queue (write its id "
                        "to taken_id, registers 290-291), wait for the tracker's echo and print what was taken")
    p.set_defaults(func=run_sim)

    plc = sub.add_parser("plc", help="PLC helpers (plc map: the register map)")
    plc_sub = plc.add_subparsers(dest="plc_command", metavar="COMMAND", required=True)
    m = plc_sub.add_parser("map", help="print the register map (0-based addresses and 4xxxx numbers)",
                           description="The Modbus holding registers the tracker writes (contract sections 4 and "
                           "4b) and the one the PLC writes (taken_id).")
    m.add_argument("--format", choices=FORMATS, default="text", help="text table (default), csv or markdown")
    m.add_argument("--base", type=int, default=0, help="the --plc-base the tracker runs with (default 0)")
    m.set_defaults(func=run_map)


def run_map(args: argparse.Namespace) -> int:
    if not 0 <= args.base <= MAX_BASE:
        raise BadInput(f"--base: expected 0-{MAX_BASE} (registers base+0 to base+299 must fit), got {args.base}")
    sys.stdout.write(render(args.format, args.base))
    return 0


def run_sim(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        raise BadInput(f"--port: expected 0-65535, got {args.port}")
    if args.arm_every is not None and not 1 <= args.arm_every <= 3_600_000:
        raise BadInput(f"--arm-every: expected 1-3600000 ms, got {args.arm_every:g}")
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        sim = PlcSimulator(args.host, args.port, word_order=WordOrder(args.word_order)).start()
        arm = Arm(sim, args.arm_every / 1000).start() if args.arm_every is not None else None
        try:
            # The port line is for people and for scripts that start it with --port 0.
            print(f"tracker: plc-sim listening on {args.host}:{sim.port} (holding registers 0-{sim.size - 1}, "
                  f"any unit id); Ctrl-C to stop", flush=True)
            while not stop.wait(0.5):
                if not sim.running:
                    log.error("plc-sim: the server stopped")
                    return 1
        finally:
            if arm is not None:
                arm.stop()
            sim.stop()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    took = f", the arm took {len(arm.takes)} parts" if arm is not None else ""
    print(f"tracker: plc-sim stopped after {sim.write_count} writes{took}", flush=True)
    return 0
