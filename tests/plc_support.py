"""Shared helpers of the PLC tests: a small scene rendered once, a scriptable camera, mbpoll, polling."""

from __future__ import annotations

import dataclasses
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tracker.health import Health
from tracker.pipeline import Pipeline
from tracker.runner import Runner
from tracker.scenes import nadir, resized
from tracker.sources import Frame, FrameSource
from tracker.synthetic import CameraSpec, PartSpec, Renderer, SceneSpec

MBPOLL = shutil.which("mbpoll") or "/usr/bin/mbpoll"
TRACKER = str(Path(sys.executable).with_name("tracker"))
DEADLINE_S = 10.0


def small_scene(n_frames: int = 100):
    """A fast 80x50 mm part crossing a 320x240 view: in view (tracked) from frame ~13 to ~95."""
    return resized(dataclasses.replace(nadir(speed_mm_s=600), n_frames=n_frames, supersample=2, blur_samples=1),
                   320, 240)


class Rendered:
    """A scene rendered once (frames + calibration), replayed by any number of ScriptedCameras."""

    def __init__(self, scene) -> None:
        renderer = Renderer(scene)
        self.calibration = renderer.calibration
        self.frames = [(renderer.render(i)[0], scene.t_ns(i)) for i in range(scene.n_frames)]


class ScriptedCamera(FrameSource):
    """Stands in for a physical camera (the one thing tests may mock): yields pre-rendered frames
    stamped on arrival, and runs ``hooks[k]()`` just before frame k, i.e. after frame k-1 was
    processed and handed to every sink."""

    def __init__(self, rendered: Rendered, hooks: dict[int, Callable[[], None]] | None = None) -> None:
        self.name = "scripted camera"
        self.rendered = rendered
        self.calibration = rendered.calibration
        self.hooks = hooks or {}
        self.arrival_ns: list[int] = []

    def __iter__(self):
        for index, (image, t_ns) in enumerate(self.rendered.frames):
            if index in self.hooks:
                self.hooks[index]()
            now = time.monotonic_ns()
            self.arrival_ns.append(now)
            yield Frame(index, t_ns, image, now)


def run_loop(source: ScriptedCamera, sinks: list, health: Health | None = None):
    runner = Runner(source, Pipeline(source.calibration), sinks, health or Health())
    return runner.run()


def wait_until(predicate: Callable[[], bool], what: str, deadline_s: float = DEADLINE_S) -> None:
    """Poll (never a bare sleep) until ``predicate()``; fail naming ``what`` after the deadline."""
    end = time.monotonic() + deadline_s
    while not predicate():
        if time.monotonic() > end:
            pytest.fail(f"timed out after {deadline_s} s waiting for {what}")
        time.sleep(0.01)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def port_open(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
        return True
    except OSError:
        return False


def start_sim_process(port: int, *extra: str) -> subprocess.Popen:
    """The real ``tracker plc-sim`` in a subprocess; returns once it listens."""
    proc = subprocess.Popen([TRACKER, "plc-sim", "--port", str(port), *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    wait_until(lambda: proc.poll() is not None or port_open(port), f"plc-sim to listen on {port}")
    assert proc.poll() is None, f"plc-sim exited: {proc.stderr.read()}"
    return proc


def stop_process(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> tuple[str, str]:
    if proc.poll() is None:
        os.kill(proc.pid, sig)
    out, err = proc.communicate(timeout=DEADLINE_S)
    return out, err


def require_mbpoll() -> None:
    """Skip the calling test where mbpoll is absent (in the test's own thread: a skip raised in a
    reader thread is only a thread's exception)."""
    if not os.path.exists(MBPOLL):
        pytest.skip("mbpoll is not installed (.ci/run installs the Debian package)")


def mbpoll(port: int, ref: int, count: int, kind: str, big_endian: bool, unit: int = 1) -> dict[int, str]:
    """Read holding registers with mbpoll (0-based references): {reference: printed value}."""
    require_mbpoll()
    cmd = [MBPOLL, "-m", "tcp", "-a", str(unit), "-0", "-r", str(ref), "-c", str(count), "-t", kind, "-1",
           "-o", "2", "-p", str(port), *(["-B"] if big_endian else []), "127.0.0.1"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=DEADLINE_S)
    assert proc.returncode == 0, f"mbpoll failed: {proc.stdout}{proc.stderr}"
    values = dict(re.findall(r"^\[(\d+)\]:\s+(\S+)", proc.stdout, flags=re.M))
    return {int(k): v for k, v in values.items()}


def mbpoll_write_u32(port: int, ref: int, value: int, big_endian: bool, unit: int = 1) -> None:
    """Write one 32-bit value (two holding registers, one request) with mbpoll, as a PLC program would."""
    if not os.path.exists(MBPOLL):
        pytest.skip("mbpoll is not installed (.ci/run installs the Debian package)")
    cmd = [MBPOLL, "-m", "tcp", "-a", str(unit), "-0", "-r", str(ref), "-t", "4:int", "-o", "2", "-p", str(port),
           *(["-B"] if big_endian else []), "127.0.0.1", str(value)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=DEADLINE_S)
    assert proc.returncode == 0 and "Written 1 references" in proc.stdout, f"mbpoll failed: {proc.stdout}{proc.stderr}"


def queue_scene(n_parts: int, n_frames: int = 60, vx_mm_s: float = 250.0, vy_mm_s: float = 120.0):
    """``n_parts`` (2-6) flat parts of different sizes in three lanes entering a 320x240 view one after the
    other and moving together at (vx, vy). The belt runs diagonally across the view, so a part that
    enters later can be further along the belt than one already in view: pick order is not id order."""
    lanes = (-210.0, 110.0, -50.0)
    sizes = ((80, 50), (60, 40), (70, 45), (90, 35), (50, 50), (65, 30))
    parts = tuple(PartSpec(*sizes[i], 0, -470.0 - 70.0 * i, lanes[i % 3], 15.0 * i, vx_mm_s, vy_mm_s,
                           intensity=170 + 10 * i) for i in range(n_parts))
    scene = SceneSpec(CameraSpec(), parts, fps=30.0, n_frames=n_frames, supersample=2, blur_samples=1)
    return resized(scene, 320, 240)
