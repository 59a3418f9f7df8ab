"""One view's own height (--part-height auto): how far each view's own fit puts it from the truth.

    .venv/bin/python bench/view_heights.py [--json]

A refining view is measured as a box of the track's height and fitted once more with its height and
size free (measure.Measurer._own_shape): what it tells of the height on its own is what the track adds
up. Here every view of bench/heights.py's boxes (and 8 and 15 mm, heights the vote does not try) is
given its true height as the track's, and its own reading is compared with the truth. Views that
tell the height less surely than track.view_height_told_sigma_mm (they show hardly any side) are
left out, as the track leaves them out. Prints, per scene, how many views tell it, the median and 90th
percentile of their errors, how many claim to be sure (1 sigma within 0.3 mm) but are 1 mm off or
more (what the track's estimate cannot average away), and each view's error over the sigma it claims:
its median (a normal's: 0.67) and how many are beyond 3 (a normal's: 0.3 %).
"""

from __future__ import annotations

import argparse
import json
import sys
from multiprocessing import Pool
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402
from heights import box_scene  # noqa: E402

from tracker.config import MeasureConfig, TrackerConfig  # noqa: E402
from tracker.evaluate import own_height_readings  # noqa: E402
from tracker.pipeline import Pipeline  # noqa: E402
from tracker.synthetic import Renderer  # noqa: E402

SCENES = [(h, t) for h in (5.0, 8.0, 10.0, 15.0, 20.0, 60.0) for t in (0.0, 10.0, 20.0)]
# A view this sure of its height (1 sigma, mm) that is this far off (mm) is one the estimate cannot
# average away.
_SURE_MM, _OFF_MM = 0.3, 1.0


def view_errors(height_mm: float, tilt_deg: float) -> dict:
    """Each telling view's own height error (mm) and claimed sigma for one box scene."""
    scene = box_scene(height_mm, tilt_deg)
    renderer = Renderer(scene)
    pipeline = Pipeline(renderer.calibration, TrackerConfig(measure=MeasureConfig(estimate_height=True)))
    frames = (renderer.render(i) for i in range(scene.n_frames))
    readings = own_height_readings(pipeline, scene, frames, height_mm)
    errors, sigmas = [e for e, _ in readings], [s for _, s in readings]
    err, sig = np.abs(errors), np.array(sigmas)
    return {"scene": f"{height_mm:g} mm, {tilt_deg:g} deg", "views": len(err),
            "median_mm": float(np.median(err)) if len(err) else float("nan"),
            "p90_mm": float(np.percentile(err, 90)) if len(err) else float("nan"),
            "mean_mm": float(np.mean(errors)) if len(err) else float("nan"),
            "sure_but_off": int(np.sum((sig <= _SURE_MM) & (err >= _OFF_MM))),
            "ratio_median": float(np.median(err / sig)) if len(err) else float("nan"),
            "beyond_3": int(np.sum(err > 3.0 * sig))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    with Pool(2) as pool:
        rows = pool.starmap(view_errors, SCENES)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print("| box, camera tilt | views telling the height | error median / p90 (mm) | mean (mm) "
          f"| sure to {_SURE_MM} mm but {_OFF_MM} mm off | error / claimed sigma: median, beyond 3 |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['views']} | {r['median_mm']:.2f} / {r['p90_mm']:.2f} | {r['mean_mm']:+.2f} "
              f"| {r['sure_but_off']} | {r['ratio_median']:.2f}, {r['beyond_3']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
