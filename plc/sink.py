"""``tracker run``'s PLC output: which writer, to where, from the command-line options."""

from __future__ import annotations

import argparse
import dataclasses
import logging

from plc.arm import Arm
from plc.encode import WordOrder
from plc.link import DatastoreLink, ModbusLink
from plc.options import DEFAULT_SIM_HOST, DEFAULT_SIM_PORT, PlcOptions, parse_endpoint
from plc.registers import SERVER_REGISTERS
from plc.sim import PlcSimulator
from plc.writer import PlcWriter
from tracker.health import Health

log = logging.getLogger(__name__)

# The demo's arm takes a part this often: several takes in the demo's 8 s, few enough lines to read.
DEMO_ARM_EVERY_S = 1.0


def open_plc_sink(args: argparse.Namespace, health: Health, demo: bool) -> PlcWriter | None:
    """--plc HOST:PORT: write into that PLC; --plc-mode server: serve the map ourselves (--plc is then the
    address to listen on); the demo without --plc/--no-plc: write into an embedded simulator; else None."""
    if args.no_plc:
        return None
    server = args.plc_mode == "server"
    if not args.plc and not server and not demo:
        return None
    host, port = parse_endpoint(args.plc) if args.plc else (DEFAULT_SIM_HOST, DEFAULT_SIM_PORT)
    # Validate every option before anything listens or connects.
    options = PlcOptions(host, port, unit=args.plc_unit, base=args.plc_base,
                         word_order=WordOrder(args.plc_word_order))
    if server:
        sim = PlcSimulator(host, port, registers=options.base + SERVER_REGISTERS, word_order=options.word_order,
                           label=f"tracker's PLC server {host}:{port}").start()
        log.info("PLC: serving the register map on %s:%d (base %d) for the arm to poll", host, sim.port, options.base)
        return PlcWriter(DatastoreLink(sim), options, health, owned=(sim,))
    if args.plc:
        return PlcWriter(ModbusLink(options), options, health)
    # The demo: an embedded simulator on a free port, so it never collides with a real plc-sim.
    sim = PlcSimulator(host, 0, registers=options.base + SERVER_REGISTERS,
                       word_order=options.word_order).start()
    # The simulator also plays the arm, so the demo shows the queue handshake (contract section 4b).
    arm = Arm(sim, DEMO_ARM_EVERY_S, base=options.base).start()
    log.info("demo: writing to the embedded PLC simulator on %s:%d; its arm takes the first part of the queue "
             "every %g s", host, sim.port, DEMO_ARM_EVERY_S)
    options = dataclasses.replace(options, port=sim.port)
    return PlcWriter(ModbusLink(options), options, health, owned=(arm, sim))
