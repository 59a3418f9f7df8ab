"""belt-tracker benchmark: every speed figure of the project next to its target, in one table.

    make bench                       # the table (and where each microsecond of a frame goes)
    .venv/bin/python bench/bench.py --json > bench.json
    .venv/bin/python bench/bench.py --sizes 1280x720,1920x1080   # stage detail at 1080p too
    .venv/bin/python bench/bench.py --soak 1000000

On 1280x720 synthetic scenes (a part crossing a tilted, distorting camera's view
at 600 mm/s, 60 fps; five parts in view for the five-part figure), measured in
one run: the vision core with one and five parts; the whole `tracker run` as a
process (start-up and decode included) on a raw video against the seed method as
a process, alone and with --record, as ratios of runs made alternately; the loop
with PLC writes to a simulator on loopback, with and without recording, and its
capture-to-register latency; the recorder alone; the start-up of `tracker --help`
and `tracker plc map`. Then per stage the median and p99 time per frame, and
peak RSS. Numbers, not assertions: the targets are printed beside them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from tracker import calibration as calib_io  # noqa: E402
from tracker.pipeline import STAGES, Pipeline  # noqa: E402
from tracker.scenes import resized, tilted  # noqa: E402
from tracker.seed import SeedMethod  # noqa: E402
from tracker.sources import VideoFileSource  # noqa: E402
from tracker.synthetic import Renderer  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TARGET_CORE_FPS = 2000
TARGET_CORE_5_FPS = 1000
TARGET_RUN_RATIO = 5.0
TARGET_RECORD_RATIO = 3.0
TARGET_FULL_FPS = 300
TARGET_LATENCY_MS = 3.0
TARGET_STARTUP_S = 0.3
TARGET_RECORDER_FPS = 300
# Frames of the raw video the whole process runs on (the figures: 492 at 720p).
PROCESS_FRAMES = 492
# Runs of each process, made alternately so a noisy neighbour weighs on all alike.
PROCESS_RUNS = 3
STARTUP_RUNS = 5


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def current_rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def render(width: int, height: int) -> tuple[object, list[np.ndarray]]:
    scene = resized(tilted(600.0), width, height)
    renderer = Renderer(scene)
    return scene, renderer.calibration, [renderer.render(i)[0] for i in range(scene.n_frames)]


def percentiles(ns: list[int]) -> dict:
    a = np.asarray(ns, dtype=np.float64) / 1e3
    return {"median_us": float(np.median(a)), "p99_us": float(np.percentile(a, 99))}


def time_core(calib, frames, scene, repeats: int, threads: int | None) -> dict:
    """The vision core (segment + undistort + measure + track) over the frames, cycled."""
    if threads is not None:
        cv2.setNumThreads(threads)
    pipeline = Pipeline(calib)
    stages = {s: [] for s in STAGES}
    total = []
    n = len(frames)
    dt_ns = scene.t_ns(1)
    for i in range(repeats * n):
        t0 = time.perf_counter_ns()
        pipeline.process(i, frames[i % n], i * dt_ns)
        total.append(time.perf_counter_ns() - t0)
        for s in STAGES:
            stages[s].append(pipeline.stage_ns[s])
    cv2.setNumThreads(-1)
    return {"fps": 1e9 / float(np.mean(total)), "stages": {s: percentiles(v) for s, v in stages.items()},
            "total": percentiles(total)}


def time_seed(calib, frames, scene, repeats: int) -> dict:
    seed = SeedMethod(calib)
    total = []
    n = len(frames)
    for i in range(repeats * n):
        t0 = time.perf_counter_ns()
        seed.process(i, frames[i % n], scene.t_ns(i))
        total.append(time.perf_counter_ns() - t0)
    return {"fps": 1e9 / float(np.mean(total)), "total": percentiles(total)}


def write_raw_video(path: Path, frames: list[np.ndarray], fps: float, repeats: int) -> None:
    h, w = frames[0].shape
    writer = cv2.VideoWriter(str(path), 0, fps, (w, h), isColor=False)  # fourcc 0: uncompressed
    for _ in range(repeats):
        for f in frames:
            writer.write(f)
    writer.release()


def time_decode(path: Path) -> dict:
    source = VideoFileSource(str(path))
    ns, t0 = [], time.perf_counter_ns()
    for _frame in source:
        t1 = time.perf_counter_ns()
        ns.append(t1 - t0)
        t0 = t1
    source.close()
    return {"frames": len(ns), **percentiles(ns)}


def five_parts(width: int = 1280, height: int = 720):
    """Five parts in view at once, crossing slowly under the tilted, distorting camera."""
    from tracker.synthetic import PartSpec  # noqa: PLC0415

    base = tilted(300.0)
    parts = tuple(PartSpec(70, 45, 0, -330 + 150 * k, -120 + 60 * k, 25 * k - 40, 120.0, 40.0) for k in range(5))
    # 70 frames: all five stay wholly in view (the fifth starts to leave at frame ~75).
    scene = resized(replace(base, parts=parts, n_frames=70), width, height)
    renderer = Renderer(scene)
    return scene, renderer.calibration, [renderer.render(i)[0] for i in range(scene.n_frames)]


def run_process(argv: list[str]) -> float:
    """Wall time of a fresh Python process (interpreter start and imports included)."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, *argv], capture_output=True, text=True, cwd=ROOT)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    return elapsed


def time_processes(video: Path, calib_path: Path, workdir: Path, frames: int) -> dict:
    """`tracker run` (alone, with --record) against the seed method, each as a whole process on the
    same raw video, run alternately; frames/s from the median wall time, ratios from the medians."""
    run = ["-m", "tracker", "run", "--source", str(video), "--calibration", str(calib_path), "--no-plc", "--quiet"]
    variants = {
        "seed": [str(Path(__file__).resolve()), "--seed-process", str(video), str(calib_path)],
        "run": run,
        "run_record": [*run, "--record", str(workdir / "process.mcap")],
    }
    times: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(PROCESS_RUNS):
        for name, argv in variants.items():
            (workdir / "process.mcap").unlink(missing_ok=True)
            times[name].append(run_process(argv))
    median = {k: statistics.median(v) for k, v in times.items()}
    return {"frames": frames, "seconds": median, "fps": {k: frames / v for k, v in median.items()},
            "run_vs_seed": median["seed"] / median["run"], "record_vs_seed": median["seed"] / median["run_record"]}


def time_startup() -> dict:
    """Median wall time of `tracker --help` and `tracker plc map` (fresh processes)."""
    out = {}
    for name, argv in (("help", ["--help"]), ("plc_map", ["plc", "map"])):
        out[name] = statistics.median(run_process(["-m", "tracker", *argv]) for _ in range(STARTUP_RUNS))
    return out


def time_recorder(calib, frames, scene, workdir: Path) -> dict:
    """The recorder alone at 720p (bench/record_bench.py's measurement, protobuf)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from record_bench import throughput  # noqa: PLC0415

    pipeline = Pipeline(calib)
    results = [pipeline.process(i, f, scene.t_ns(i)) for i, f in enumerate(frames)]
    return throughput(calib, frames, results, scene, 600, workdir / "recorder.mcap")


def seed_process_main(video: str, calib_path: str) -> int:
    """The seed method as a process of its own: load the calibration, decode, process every frame."""
    seed = SeedMethod(calib_io.load(calib_path))
    source = VideoFileSource(video)
    n = 0
    for frame in source:
        seed.process(frame.index, frame.image, frame.t_ns)
        n += 1
    source.close()
    print(f"seed: {n} frames")
    return 0


class TimedSink:
    """Wraps a sink to time ``submit`` (what the loop itself spends on publishing/recording)."""

    def __init__(self, sink) -> None:
        self.sink = sink
        self.ns: list[int] = []

    def submit(self, frame, result) -> None:
        t0 = time.perf_counter_ns()
        self.sink.submit(frame, result)
        self.ns.append(time.perf_counter_ns() - t0)

    def status(self) -> str:
        return self.sink.status()

    def close(self) -> None:
        self.sink.close()


def time_full_loop(video: Path, calib, record_to: Path | None) -> dict:
    """The loop with PLC writes to a local simulator (and, if available, recording): fps, latency."""
    from plc.encode import WordOrder  # noqa: PLC0415
    from plc.link import ModbusLink  # noqa: PLC0415
    from plc.options import PlcOptions  # noqa: PLC0415
    from plc.sim import PlcSimulator  # noqa: PLC0415
    from plc.writer import PlcWriter  # noqa: PLC0415
    from tracker.health import Health  # noqa: PLC0415
    from tracker.runner import Runner  # noqa: PLC0415
    from tracker.sources import Prefetch  # noqa: PLC0415

    health = Health()
    sim = PlcSimulator("127.0.0.1", 0).start()
    options = PlcOptions("127.0.0.1", sim.port, unit=1, base=0, word_order=WordOrder("ABCD"))
    writer = PlcWriter(ModbusLink(options), options, health, owned=(sim,))
    sinks = {"publish": TimedSink(writer)}
    recorder = make_recorder(record_to, calib, health) if record_to else None
    if recorder is not None:
        sinks["record"] = TimedSink(recorder)
    runner = Runner(Prefetch(VideoFileSource(str(video))), Pipeline(calib), list(sinks.values()), health)
    summary = runner.run()
    latency = list(writer.stats.capture_to_register_ns)
    result = {"fps": summary.frames / summary.seconds, "frames": summary.frames,
              "capture_to_register": percentiles(latency) if latency else None,
              "recorded": recorder is not None}
    result["stages"] = {name: percentiles(t.ns) for name, t in sinks.items()}
    return result


def make_recorder(path: Path, calib, health):
    """The MCAP recorder sink, as `tracker run --record` opens it."""
    from tracker.config import TrackerConfig  # noqa: PLC0415
    from tracker.recording.writer import Recorder, RunInfo  # noqa: PLC0415

    return Recorder.open(str(path), RunInfo(calib, TrackerConfig(), "bench", None), health)


def bench_size(width: int, height: int, repeats: int, workdir: Path, summary: bool) -> dict:
    """Stage detail at one size; with ``summary`` (720p) also every figure of the summary table."""
    scene, calib, frames = render(width, height)
    result: dict = {"size": f"{width}x{height}", "frames_per_pass": len(frames)}
    result["core_1_thread"] = time_core(calib, frames, scene, repeats, threads=1)
    result["core_default_threads"] = time_core(calib, frames, scene, repeats, threads=None)
    result["seed_core"] = time_seed(calib, frames, scene, repeats)
    video = workdir / f"raw_{width}x{height}.avi"
    calib_path = workdir / f"calib_{width}x{height}.yaml"
    passes = max(repeats, -(-PROCESS_FRAMES // len(frames)))
    write_raw_video(video, frames, scene.fps, passes)
    calib_io.save(calib, calib_path)
    result["decode"] = time_decode(video)
    result["plc_loop"] = time_full_loop(video, calib, None)
    result["full_loop"] = time_full_loop(video, calib, workdir / "bench.mcap")
    if summary:
        scene5, calib5, frames5 = five_parts(width, height)
        result["core_5_parts"] = time_core(calib5, frames5, scene5, repeats, threads=1) | {"frames": len(frames5)}
        result["processes"] = time_processes(video, calib_path, workdir, len(frames) * passes)
        result["recorder"] = time_recorder(calib, frames, scene, workdir)
    video.unlink()
    return result


def summary_rows(r: dict, startup: dict) -> list[dict]:
    """Every figure of the speed targets, measured in this run, with its target and whether it is met."""
    p, lat = r["processes"], r["plc_loop"]["capture_to_register"]
    p99 = lat["p99_us"] / 1e3 if lat else float("nan")
    rows = [
        ("vision core, 1 part in view, 1 thread", f"{r['core_1_thread']['fps']:,.0f} frames/s",
         f">= {TARGET_CORE_FPS:,} frames/s", r["core_1_thread"]["fps"] >= TARGET_CORE_FPS),
        ("vision core, 5 parts in view, 1 thread", f"{r['core_5_parts']['fps']:,.0f} frames/s",
         f">= {TARGET_CORE_5_FPS:,} frames/s", r["core_5_parts"]["fps"] >= TARGET_CORE_5_FPS),
        (f"`tracker run --no-plc` vs the seed method, whole processes ({p['frames']} frames)",
         f"{p['run_vs_seed']:.2f}x ({p['fps']['run']:.0f} vs {p['fps']['seed']:.0f} frames/s)",
         f">= {TARGET_RUN_RATIO:g}x", p["run_vs_seed"] >= TARGET_RUN_RATIO),
        ("`tracker run --no-plc --record` vs the seed method",
         f"{p['record_vs_seed']:.2f}x ({p['fps']['run_record']:.0f} frames/s)",
         f">= {TARGET_RECORD_RATIO:g}x", p["record_vs_seed"] >= TARGET_RECORD_RATIO),
        ("loop with PLC writes and recording", f"{r['full_loop']['fps']:.0f} frames/s",
         f">= {TARGET_FULL_FPS} frames/s", r["full_loop"]["fps"] >= TARGET_FULL_FPS),
        ("capture-to-register latency p99, PLC on loopback", f"{p99:.2f} ms",
         f"<= {TARGET_LATENCY_MS:g} ms", p99 <= TARGET_LATENCY_MS),
        ("`tracker --help` start-up", f"{startup['help']:.2f} s", f"<= {TARGET_STARTUP_S:g} s",
         startup["help"] <= TARGET_STARTUP_S),
        ("`tracker plc map` start-up", f"{startup['plc_map']:.2f} s", f"<= {TARGET_STARTUP_S:g} s",
         startup["plc_map"] <= TARGET_STARTUP_S),
        ("recorder alone (encode, compress, write)", f"{r['recorder']['fps']:.0f} frames/s",
         f">= {TARGET_RECORDER_FPS} frames/s", r["recorder"]["fps"] >= TARGET_RECORDER_FPS),
    ]
    return [{"figure": f, "measured": m, "target": t, "met": bool(ok)} for f, m, t, ok in rows]


def soak(frames_total: int) -> dict:
    scene, calib, frames = render(1280, 720)
    pipeline = Pipeline(calib)
    n = len(frames)
    dt_ns = scene.t_ns(1)
    start_rss = current_rss_mb()
    checkpoints = []
    t0 = time.perf_counter()
    for i in range(frames_total):
        pipeline.process(i, frames[i % n], i * dt_ns)
        if (i + 1) % max(1, frames_total // 10) == 0:
            checkpoints.append((i + 1, round(current_rss_mb(), 1)))
            # Progress as it goes: a long soak that is stopped early still says what it saw.
            print(f"soak: {i + 1} frames, RSS {checkpoints[-1][1]} MB (start {start_rss:.1f} MB)",
                  file=sys.stderr, flush=True)
    return {"frames": frames_total, "seconds": time.perf_counter() - t0, "rss_start_mb": start_rss,
            "rss_end_mb": current_rss_mb(), "rss_checkpoints_mb": checkpoints}


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, OpenCV {cv2.__version__}"


def print_summary(rows: list[dict]) -> None:
    print(f"machine: {machine()}")
    print("\n| 1280x720 | measured | target | |")
    print("|---|---|---|---|")
    for row in rows:
        print(f"| {row['figure']} | {row['measured']} | {row['target']} | {'met' if row['met'] else 'NOT met'} |")


def print_table(results: list[dict]) -> None:
    for r in results:
        print(f"\n== {r['size']} ({r['frames_per_pass']} frames per pass) ==")
        print(f"{'stage':<12}{'median us':>12}{'p99 us':>12}")
        print(f"{'decode':<12}{r['decode']['median_us']:>12.1f}{r['decode']['p99_us']:>12.1f}")
        for s, v in r["core_1_thread"]["stages"].items():
            print(f"{s:<12}{v['median_us']:>12.1f}{v['p99_us']:>12.1f}")
        t = r["core_1_thread"]["total"]
        print(f"{'core total':<12}{t['median_us']:>12.1f}{t['p99_us']:>12.1f}")
        print(f"vision core: {r['core_1_thread']['fps']:.0f} frames/s on 1 thread, "
              f"{r['core_default_threads']['fps']:.0f} with default threads; seed method core: "
              f"{r['seed_core']['fps']:.0f} frames/s")
        for full in (r["plc_loop"], r["full_loop"]):
            what = "PLC writes + recording" if full["recorded"] else "PLC writes"
            lat = full["capture_to_register"]
            lat_text = f"p50 {lat['median_us'] / 1e3:.2f} ms, p99 {lat['p99_us'] / 1e3:.2f} ms" if lat else "n/a"
            print(f"with {what}: {full['fps']:.0f} frames/s; capture-to-register {lat_text}")
            for name, v in full["stages"].items():
                print(f"  {name} (loop's share): median {v['median_us']:.1f} us, p99 {v['p99_us']:.1f} us")
    print(f"\npeak RSS: {peak_rss_mb():.0f} MB")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--repeats", type=int, default=3, help="passes over each scene (default 3)")
    parser.add_argument("--sizes", default="1280x720", help="stage detail at these sizes (the summary: 720p)")
    parser.add_argument("--soak", type=int, metavar="FRAMES", help="only run the memory soak for FRAMES frames")
    parser.add_argument("--seed-process", nargs=2, metavar=("VIDEO", "CALIB"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.seed_process:
        return seed_process_main(*args.seed_process)
    if args.soak:
        result = soak(args.soak)
        print(json.dumps(result, indent=1) if args.json else
              f"soak: {result['frames']} frames in {result['seconds']:.0f} s; RSS {result['rss_start_mb']:.1f} MB "
              f"at start, {result['rss_end_mb']:.1f} MB at end; checkpoints {result['rss_checkpoints_mb']}")
        return 0
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    if (1280, 720) not in sizes:
        sizes.insert(0, (1280, 720))
    startup = time_startup()
    with tempfile.TemporaryDirectory(prefix="belt-bench-") as tmp:
        results = [bench_size(w, h, args.repeats, Path(tmp), (w, h) == (1280, 720)) for w, h in sizes]
    rows = summary_rows(results[sizes.index((1280, 720))], startup)
    if args.json:
        print(json.dumps({"machine": machine(), "summary": rows, "startup_s": startup, "peak_rss_mb": peak_rss_mb(),
                          "results": results}, indent=1))
    else:
        print_summary(rows)
        print_table(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
