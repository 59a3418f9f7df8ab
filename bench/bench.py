"""belt-tracker benchmark: where every microsecond of a frame goes.

    make bench                       # table
    .venv/bin/python bench/bench.py --json > bench.json
    .venv/bin/python bench/bench.py --soak 1000000

For 1280x720 and 1920x1080 synthetic scenes (a part crossing a tilted,
distorting camera's view at 600 mm/s, 60 fps), prints per stage the median and
p99 time per frame, the vision core's frames/s with one thread and with
OpenCV's default, the whole `tracker run` on a raw video against the seed
method in the same run (as a ratio), and peak RSS. Numbers, not assertions: the
targets are printed beside them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from tracker import calibration as calib_io  # noqa: E402
from tracker.cli import main as tracker_main  # noqa: E402
from tracker.pipeline import STAGES, Pipeline  # noqa: E402
from tracker.scenes import resized, tilted  # noqa: E402
from tracker.seed import SeedMethod  # noqa: E402
from tracker.sources import VideoFileSource  # noqa: E402
from tracker.synthetic import Renderer  # noqa: E402

TARGET_CORE_FPS = 2000
TARGET_RUN_RATIO = 10.0
TARGET_FULL_FPS = 300
TARGET_LATENCY_MS = 3.0
SIZES = ((1280, 720), (1920, 1080))


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


def time_whole_run(video: Path, calib_path: Path, extra: list[str]) -> float:
    """frames/s of the real `tracker run` (in-process) on a raw video."""
    out = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = tracker_main(["run", "--source", str(video), "--calibration", str(calib_path), "--quiet", *extra])
    elapsed = time.perf_counter() - t0
    if code != 0:
        raise RuntimeError(f"tracker run exited {code}")
    frames = int(out.getvalue().split("tracker: ")[1].split(" frames")[0])
    return frames / elapsed


def time_seed_process(video: Path, calib) -> float:
    """The seed method as a whole process would run it: decode + grey + seed, per frame."""
    seed = SeedMethod(calib)
    t0 = time.perf_counter()
    source = VideoFileSource(str(video))
    n = 0
    for frame in source:
        seed.process(frame.index, frame.image, frame.t_ns)
        n += 1
    source.close()
    return n / (time.perf_counter() - t0)


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


def bench_size(width: int, height: int, repeats: int, workdir: Path) -> dict:
    scene, calib, frames = render(width, height)
    result: dict = {"size": f"{width}x{height}", "frames_per_pass": len(frames)}
    result["core_1_thread"] = time_core(calib, frames, scene, repeats, threads=1)
    result["core_default_threads"] = time_core(calib, frames, scene, repeats, threads=None)
    result["seed_core"] = time_seed(calib, frames, scene, repeats)
    video = workdir / f"raw_{width}x{height}.avi"
    calib_path = workdir / f"calib_{width}x{height}.yaml"
    write_raw_video(video, frames, scene.fps, repeats)
    calib_io.save(calib, calib_path)
    result["decode"] = time_decode(video)
    result["run_no_plc_fps"] = time_whole_run(video, calib_path, ["--no-plc"])
    result["seed_process_fps"] = time_seed_process(video, calib)
    result["run_vs_seed"] = result["run_no_plc_fps"] / result["seed_process_fps"]
    result["plc_loop"] = time_full_loop(video, calib, None)
    result["full_loop"] = time_full_loop(video, calib, workdir / "bench.mcap")
    video.unlink()
    return result


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


def print_table(results: list[dict]) -> None:
    print(f"machine: {machine()}")
    for r in results:
        print(f"\n== {r['size']} ({r['frames_per_pass']} frames per pass) ==")
        print(f"{'stage':<12}{'median us':>12}{'p99 us':>12}")
        print(f"{'decode':<12}{r['decode']['median_us']:>12.1f}{r['decode']['p99_us']:>12.1f}")
        for s, v in r["core_1_thread"]["stages"].items():
            print(f"{s:<12}{v['median_us']:>12.1f}{v['p99_us']:>12.1f}")
        t = r["core_1_thread"]["total"]
        print(f"{'core total':<12}{t['median_us']:>12.1f}{t['p99_us']:>12.1f}")
        print(f"vision core: {r['core_1_thread']['fps']:.0f} frames/s on 1 thread, "
              f"{r['core_default_threads']['fps']:.0f} with default threads (target >= {TARGET_CORE_FPS} at 720p)")
        print(f"seed method core: {r['seed_core']['fps']:.0f} frames/s")
        print(f"tracker run --no-plc on a raw video: {r['run_no_plc_fps']:.0f} frames/s; seed as a process: "
              f"{r['seed_process_fps']:.0f} frames/s; ratio {r['run_vs_seed']:.2f} (target >= {TARGET_RUN_RATIO})")
        for full in (r["plc_loop"], r["full_loop"]):
            what = "PLC writes + recording" if full["recorded"] else "PLC writes"
            lat = full["capture_to_register"]
            lat_text = f"p50 {lat['median_us'] / 1e3:.2f} ms, p99 {lat['p99_us'] / 1e3:.2f} ms" if lat else "n/a"
            print(f"with {what}: {full['fps']:.0f} frames/s (target >= {TARGET_FULL_FPS} at 720p); "
                  f"capture-to-register {lat_text} (target p99 <= {TARGET_LATENCY_MS} ms)")
            for name, v in full["stages"].items():
                print(f"  {name} (loop's share): median {v['median_us']:.1f} us, p99 {v['p99_us']:.1f} us")
    print(f"\npeak RSS: {peak_rss_mb():.0f} MB")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--repeats", type=int, default=3, help="passes over each scene (default 3)")
    parser.add_argument("--sizes", default="1280x720,1920x1080")
    parser.add_argument("--soak", type=int, metavar="FRAMES", help="only run the memory soak for FRAMES frames")
    args = parser.parse_args(argv)
    if args.soak:
        result = soak(args.soak)
        print(json.dumps(result, indent=1) if args.json else
              f"soak: {result['frames']} frames in {result['seconds']:.0f} s; RSS {result['rss_start_mb']:.1f} MB "
              f"at start, {result['rss_end_mb']:.1f} MB at end; checkpoints {result['rss_checkpoints_mb']}")
        return 0
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    with tempfile.TemporaryDirectory(prefix="belt-bench-") as tmp:
        results = [bench_size(w, h, args.repeats, Path(tmp)) for w, h in sizes]
    if args.json:
        print(json.dumps({"machine": machine(), "peak_rss_mb": peak_rss_mb(), "results": results}, indent=1))
    else:
        print_table(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
