"""The PLC queue (contract section 4b) on loopback, at camera rate: the demo scene (4 parts, 30 fps) paced
like a camera, the tracker writing to a simulator whose arm takes the first listed part every 250 ms.

Prints, for client mode (the tracker reads taken_id over Modbus) and server mode (the arm writes into the
tracker's own server): the echo latency (taken_id written -> taken_echo visible), the queue write period
(between consecutive 100-219 writes received), and capture-to-register (frame arrival -> that frame's
block / queue accepted by the PLC), median and p99.

    .venv/bin/python bench/plc_queue_bench.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from plc.arm import Arm  # noqa: E402
from plc.link import DatastoreLink, ModbusLink  # noqa: E402
from plc.options import PlcOptions  # noqa: E402
from plc.registers import QUEUE_START  # noqa: E402
from plc.sim import PlcSimulator  # noqa: E402
from plc.writer import PlcWriter  # noqa: E402
from tracker.health import Health  # noqa: E402
from tracker.pipeline import Pipeline  # noqa: E402
from tracker.runner import Runner  # noqa: E402
from tracker.scenes import SyntheticSource, demo  # noqa: E402
from tracker.sources import Paced  # noqa: E402

ARM_EVERY_S = 0.25


def _ms(values) -> str:
    a = np.asarray(list(values), dtype=np.float64)
    if a.size == 0:
        return "n/a"
    return f"median {np.median(a):.1f} ms, p99 {np.percentile(a, 99):.1f} ms, max {a.max():.1f} ms (n={a.size})"


def probe_echo(mode: str, frames: int) -> list[float]:
    """Echo latency with many samples: no arm; taken_ids that are no part's, every 100 ms (same path)."""
    import threading  # noqa: PLC0415
    import time  # noqa: PLC0415

    from plc.encode import WordOrder, decode_u32, encode_u32  # noqa: PLC0415
    from plc.registers import QUEUE_FIELDS, TAKEN  # noqa: PLC0415

    health = Health()
    sim = PlcSimulator("127.0.0.1", 0).start()
    options = PlcOptions("127.0.0.1", sim.port)
    link = ModbusLink(options) if mode == "client" else DatastoreLink(sim)
    writer = PlcWriter(link, options, health, owned=(sim,))
    echo_f = QUEUE_FIELDS["taken_echo"]
    stop, out = threading.Event(), []

    def prober():
        value = 1_000_000
        while not stop.wait(0.1):
            value += 1
            sim.store(TAKEN.address, encode_u32(value, WordOrder.ABCD))
            t0 = time.monotonic()
            while time.monotonic() - t0 < 1.0:
                if decode_u32(sim.read(echo_f.address, 2), WordOrder.ABCD) == value:
                    out.append((time.monotonic() - t0) * 1000)
                    break
                time.sleep(0.001)

    thread = threading.Thread(target=prober, daemon=True)
    source = Paced(SyntheticSource(demo(n_frames=frames)))
    thread.start()
    try:
        Runner(source, Pipeline(source.calibration), [writer], health).run()
    finally:
        stop.set()
        thread.join(timeout=2)
    return out


def run(mode: str, frames: int) -> dict:
    health = Health()
    sim = PlcSimulator("127.0.0.1", 0).start()
    options = PlcOptions("127.0.0.1", sim.port)
    link = ModbusLink(options) if mode == "client" else DatastoreLink(sim)
    writer = PlcWriter(link, options, health, owned=(sim,))
    arm = Arm(sim, ARM_EVERY_S).start()
    source = Paced(SyntheticSource(demo(n_frames=frames)))
    try:
        Runner(source, Pipeline(source.calibration), [writer], health).run()
    finally:
        arm.stop()  # before the writer stops the simulator
    queue_t = [w.t_ns for w in sim.writes(QUEUE_START)]
    s = writer.stats
    return {
        "echo_ms": [t.echo_ms for t in arm.takes if t.echo_ms is not None],
        "no_echo": sum(t.echo_ms is None for t in arm.takes),
        "queue_period_ms": np.diff(queue_t) / 1e6 if len(queue_t) > 1 else [],
        "block_ms": np.asarray(s.capture_to_register_ns) / 1e6,
        "queue_ms": np.asarray(s.queue_capture_to_register_ns) / 1e6,
        "taken": s.taken, "queue_writes": s.queue_writes,
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=240, help="frames of the demo scene (30 fps; default 240)")
    args = p.parse_args()
    for mode in ("client", "server"):
        r = run(mode, args.frames)
        print(f"{mode} mode: {r['taken']} parts taken, {r['queue_writes']} queue writes, {r['no_echo']} without echo")
        print(f"  echo latency (taken_id written -> echo):   {_ms(r['echo_ms'])}")
        print(f"  echo latency, probe every 100 ms:           {_ms(probe_echo(mode, args.frames))}")
        print(f"  queue write period (100-219 received):      {_ms(r['queue_period_ms'])}")
        print(f"  capture -> block 0-44 accepted:             {_ms(r['block_ms'])}")
        print(f"  capture -> queue 100-219 accepted:          {_ms(r['queue_ms'])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
