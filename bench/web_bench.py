"""The live view costs the loop nothing: loop frames/s with no viewer and with 20 viewers polling
the image and the state, in the same run (ratios: this machine is shared and noisy).

    python bench/web_bench.py

The viewers run in another process, as browsers do: what is measured is the tracker's own cost
of serving them.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from plc_support import Rendered, ScriptedCamera, free_port, small_scene  # noqa: E402

from tracker.health import Health  # noqa: E402
from tracker.pipeline import Pipeline  # noqa: E402
from tracker.runner import Runner  # noqa: E402
from tracker.web import LiveView, WebServer  # noqa: E402


def _loop_fps(rendered: Rendered, viewers: int) -> float:
    health = Health()
    pipeline = Pipeline(rendered.calibration)
    view = LiveView(rendered.calibration, health, [], pipeline.roi_px)
    server = WebServer(view, "127.0.0.1", free_port()).start()
    viewers_proc = None
    if viewers:
        # Each viewer polls like the page does: the state every 150 ms, the image when it changed.
        code = ("import threading, time, urllib.request, sys\n"
                "def poll(i):\n"
                "    while True:\n"
                "        for path in ('state.json', 'frame.jpg'):\n"
                "            try: urllib.request.urlopen(sys.argv[1] + path, timeout=2).read()\n"
                "            except OSError: pass\n"
                "        time.sleep(0.15)\n"
                f"[threading.Thread(target=poll, args=(i,), daemon=True).start() for i in range({viewers})]\n"
                "time.sleep(3600)\n")
        viewers_proc = subprocess.Popen([sys.executable, "-c", code, server.url])
        time.sleep(0.5)  # let them connect (a benchmark, not a test: nothing is asserted)
    try:
        started = time.perf_counter()
        summary = Runner(ScriptedCamera(rendered), pipeline, [view], health).run()
        return summary.frames / (time.perf_counter() - started)
    finally:
        if viewers_proc is not None:
            viewers_proc.kill()
            viewers_proc.wait()
        server.close()


def main(argv: list[str] | None = None) -> int:
    argparse.ArgumentParser(description=__doc__).parse_args(argv)
    rendered = Rendered(small_scene(600))
    rows = []
    for _ in range(2):  # alternate, so load changes hit both alike
        rows.append((_loop_fps(rendered, 0), _loop_fps(rendered, 20)))
    alone = sum(a for a, _ in rows) / len(rows)
    watched = sum(w for _, w in rows) / len(rows)
    print(f"loop alone {alone:.0f} frames/s, with 20 viewers {watched:.0f} frames/s: ratio {watched / alone:.2f} "
          f"(320x240 scene; the viewers' threads share the same 2 cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
