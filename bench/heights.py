"""Parts with height: accuracy on rendered boxes, height given, estimated (auto) and ignored (flat).

    .venv/bin/python bench/heights.py [--json] [--quick]

Prints a Markdown table (the README's "Parts with height" figures come from it). The scenes are
not the tests' (other cameras, part sizes, shades, paths and speeds): boxes 5, 10, 20 and 60 mm
tall crossing the whole view while turning, under cameras tilted 0, 10 and 20 deg, and a pair of
parts of different heights at once, and a flat part. For auto, the height and centroid errors are split into the
frames before and after the track says its height has converged (the part's own track: not the
ghost a part in view at the start leaves behind). The last columns are the measurement stage's own
time per frame (one part in view), with the height given, flat and estimated, in the same run, and
with the height estimated its 99th percentile (the frames a part votes in). The last column is auto
without measure.learn_shades (tracker/shades.py).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from tracker.config import MeasureConfig, TrackerConfig  # noqa: E402
from tracker.evaluate import centroid_error_mm, evaluate, own_track, part_views  # noqa: E402
from tracker.pipeline import Pipeline  # noqa: E402
from tracker.synthetic import CameraSpec, PartSpec, Renderer, SceneSpec  # noqa: E402

HEIGHTS_MM = (5.0, 10.0, 20.0, 60.0)
TILTS_DEG = (0.0, 10.0, 20.0)


def box_scene(height_mm: float, tilt_deg: float) -> SceneSpec:
    cam = CameraSpec(width=560, height=420, focal_px=470.0, tilt_deg=tilt_deg, yaw_deg=-35.0, height_mm=760.0,
                     principal_offset_px=(-4.0, 3.0))
    part = PartSpec(72, 46, height_mm, -460, 40, -15, 340, -30, omega_deg_s=-16.0, intensity=175)
    return SceneSpec(cam, (part,), fps=30, n_frames=84, supersample=8, blur_samples=3, belt_level=70.0, seed=7)


def pair_scene() -> SceneSpec:
    cam = CameraSpec(width=560, height=420, focal_px=470.0, tilt_deg=15.0, yaw_deg=-35.0, height_mm=760.0)
    parts = (PartSpec(72, 46, 20.0, -460, 60, -15, 340, -30, omega_deg_s=-16.0, intensity=175),
             PartSpec(60, 40, 8.0, -520, -110, 30, 330, 10, omega_deg_s=12.0, intensity=205))
    return SceneSpec(cam, parts, fps=30, n_frames=90, supersample=8, blur_samples=3, belt_level=70.0, seed=8)


def run(scene: SceneSpec, measure: MeasureConfig, spent: dict | None = None) -> tuple[list[dict], list[dict]]:
    """Poses and truths of ``scene``; ``spent``: gets the measurement stage's mean ms per frame ("ms")
    and its 99th percentile ("p99_ms": a vote's frame fits a box at every height)."""
    renderer = Renderer(scene)
    pipeline = Pipeline(renderer.calibration, TrackerConfig(measure=measure))
    poses, truths, measure_ns = [], [], []
    for i in range(scene.n_frames):
        image, truth = renderer.render(i)
        poses.append(pipeline.process(i, image, scene.t_ns(i)).to_dict())
        measure_ns.append(pipeline.stage_ns["measure"] + pipeline.stage_ns["undistort"])
        truths.append(truth)
    if spent is not None:
        spent["ms"] = float(np.mean(measure_ns)) / 1e6
        spent["p99_ms"] = float(np.percentile(measure_ns, 99)) / 1e6
    return poses, truths


def auto_errors(poses: list[dict], truths: list[dict]) -> dict:
    """Height and centroid errors of measured objects, before and after their height converged: for
    each part, the measured object nearest it (within half its width) of the track that is so most
    often (the part's own track, not the ghost a part in view at the start leaves behind)."""
    out: dict[str, list[float]] = {"h_before": [], "h_after": [], "c_before": [], "c_after": []}
    for k in range(len(truths[0]["objects"])):
        for o, t in own_track(part_views(poses, truths, k)):
            when = "after" if o["height_converged"] else "before"
            out[f"h_{when}"].append(abs(o["height_mm"] - t["height_mm"]))
            out[f"c_{when}"].append(centroid_error_mm(o, t))
    return {k: (float(np.mean(v)) if v else math.nan) for k, v in out.items()} | {
        "converged_fraction": len(out["h_after"]) / max(1, len(out["h_after"]) + len(out["h_before"])),
        "h_after_max": float(np.max(out["h_after"])) if out["h_after"] else math.nan}


def measure_all(quick: bool = False) -> list[dict]:
    cases = [(f"{h:g} mm box, {t:g} deg tilt", box_scene(h, t), h) for h in HEIGHTS_MM for t in TILTS_DEG]
    # A flat part: what auto makes of it (given and flat are the same here).
    cases += [(f"flat part, {t:g} deg tilt", box_scene(0.0, t), 0.0) for t in (0.0, 20.0)]
    cases.append(("20 mm and 8 mm boxes at once, 15 deg tilt", pair_scene(), None))
    if quick:
        cases = cases[::4]
    rows = []
    for name, scene, height in cases:
        row = {"scene": name}
        if height is not None:
            given_ms, flat_ms = {}, {}
            given = evaluate(*run(scene, MeasureConfig(part_height_mm=height, estimate_height=False), given_ms),
                             skip_first=2).summary()
            flat = evaluate(*run(scene, MeasureConfig(estimate_height=False), flat_ms), skip_first=2).summary()
            row |= {"given": given, "flat_centroid_mean_mm": flat["centroid_mean_mm"],
                    "measure_ms": given_ms["ms"], "flat_measure_ms": flat_ms["ms"]}
        auto_ms: dict = {}
        auto_poses, auto_truths = run(scene, MeasureConfig(estimate_height=True), auto_ms)
        row["auto_measure_ms"], row["auto_measure_p99_ms"] = auto_ms["ms"], auto_ms["p99_ms"]
        row["auto"] = auto_errors(auto_poses, auto_truths) | {
            "centroid_mean_mm": evaluate(auto_poses, auto_truths, skip_first=2).summary()["centroid_mean_mm"]}
        # The same without measure.learn_shades (see the README).
        row["auto_shades"] = auto_errors(*run(scene, MeasureConfig(estimate_height=True, learn_shades=False)))
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--quick", action="store_true", help="every fourth scene only")
    args = parser.parse_args(argv)
    rows = measure_all(args.quick)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print("| scene | given: centroid mean / p95 (mm) | angle mean (deg) | length / width max (mm) | flat: centroid "
          "mean (mm) | auto: height before / after converged (mm) | auto: centroid before / after (mm) "
          "| auto: converged | measure ms/frame: given / flat / auto | auto: measure p99 ms "
          "| auto, no shades learnt: height after converged (mm), converged |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        g, a = r.get("given"), r["auto"]
        given = (f"{g['centroid_mean_mm']:.3f} / {g['centroid_p95_mm']:.3f} | {g['angle_mean_deg']:.3f} "
                 f"| {g['length_max_mm']:.2f} / {g['width_max_mm']:.2f} | {r['flat_centroid_mean_mm']:.2f}"
                 if g else "- | - | - | -")
        print(f"| {r['scene']} | {given} | {a['h_before']:.2f} / {a['h_after']:.2f} (max {a['h_after_max']:.2f}) "
              f"| {a['c_before']:.3f} / {a['c_after']:.3f} | {100 * a['converged_fraction']:.0f} % "
              f"| {r.get('measure_ms', math.nan):.1f} / {r.get('flat_measure_ms', math.nan):.1f} "
              f"/ {r['auto_measure_ms']:.1f} | {r['auto_measure_p99_ms']:.1f} "
              f"| {r['auto_shades']['h_after']:.2f} (max {r['auto_shades']['h_after_max']:.2f}), "
              f"{100 * r['auto_shades']['converged_fraction']:.0f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
