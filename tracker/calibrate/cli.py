"""``tracker calibrate intrinsics | belt | show``."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import cv2

from tracker import calibration as calibfile
from tracker.calibrate import report
from tracker.calibrate.belt import belt_from_board, belt_from_points, draw_preview, read_pairs
from tracker.calibrate.board import DETECTORS, parse_pattern
from tracker.calibrate.capture import CaptureSettings
from tracker.calibrate.images import read_all_same_size, read_grey
from tracker.calibrate.intrinsics import calibrate_intrinsics
from tracker.calibrate.settings import DEFAULTS
from tracker.errors import BadInput, TrackerError
from tracker.outputs import check_target, check_writable

CAPTURE = CaptureSettings()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="camera intrinsics and the belt pose from chessboard views")
    csub = p.add_subparsers(dest="calibrate_command", metavar="STEP", required=True)

    i = csub.add_parser("intrinsics", help="K and distortion from ~15 chessboard views")
    i.add_argument("images", nargs="+", metavar="IMAGE")
    _board_args(i, required=False, charuco=True)
    i.add_argument("--out", required=True, metavar="CALIB", help="calibration file to write (.yaml/.yml/.xml)")
    i.add_argument("--min-views", type=int, default=DEFAULTS.min_views,
                   help="fewest usable views (default %(default)s)")
    i.add_argument("--fix-k3", action="store_true", help="fit k1 k2 p1 p2 only (k3 = 0), for mild lenses")
    i.add_argument("--max-rms", type=float, default=DEFAULTS.max_rms_px,
                   help="refuse a calibration whose RMS exceeds this, px (default %(default)s)")
    i.add_argument("--report", metavar="REPORT.json", help="also write the quality report as JSON")
    i.add_argument("--preview", metavar="DIR", help="write each view with its detected corners as PNG here")
    i.set_defaults(func=run_intrinsics)

    c = csub.add_parser("capture", help="intrinsics from a live camera or a video: good views kept automatically",
                        description="Watches SRC (a camera index, a video, an image pattern) for the board and "
                        "keeps the views that are sharp and new (board moved, resized or tilted), showing "
                        "the coverage of the image and the tilt directions reached; stops when there are "
                        "enough (or at the end of a video, or on Ctrl-C), saves the views next to CALIB and "
                        "calibrates them exactly as 'calibrate intrinsics' does.")
    c.add_argument("--source", required=True, metavar="SRC", help="camera index, video file or image pattern")
    _board_args(c, required=True)
    c.add_argument("--out", required=True, metavar="CALIB", help="calibration file to write (.yaml/.yml/.xml)")
    c.add_argument("--views", metavar="DIR", help="where the kept views go (default: CALIB's name + .views); "
                   "must be new or empty")
    c.add_argument("--target-views", type=int, default=CAPTURE.target_views,
                   help="views wanted once coverage and tilts are reached (default %(default)s)")
    c.add_argument("--max-views", type=int, default=CAPTURE.max_views,
                   help="stop at this many views whatever the coverage (default %(default)s)")
    c.add_argument("--min-views", type=int, default=DEFAULTS.min_views,
                   help="fewest usable views (default %(default)s)")
    c.add_argument("--fix-k3", action="store_true", help="fit k1 k2 p1 p2 only (k3 = 0), for mild lenses")
    c.add_argument("--max-rms", type=float, default=DEFAULTS.max_rms_px,
                   help="refuse a calibration whose RMS exceeds this, px (default %(default)s)")
    c.add_argument("--report", metavar="REPORT.json", help="also write the quality report as JSON")
    c.add_argument("--web", metavar="HOST:PORT", help="show the camera, the corners found and the progress on a "
                   "read-only web page there (like tracker run --web)")
    c.add_argument("--quiet", action="store_true", help="no status line")
    c.set_defaults(func=_run_capture)

    b = csub.add_parser("belt", help="the belt pose from a board lying flat on the belt (or --points)")
    b.add_argument("image", nargs="?", metavar="IMAGE")
    _board_args(b, required=False, charuco=True)
    b.add_argument("--calibration", required=True, metavar="CALIB", help="file from 'calibrate intrinsics'")
    b.add_argument("--out", metavar="CALIB2", help="write here instead of updating CALIB in place")
    b.add_argument("--points", metavar="PAIRS.csv", help="u, v, X, Y per line (>= 4 pairs) instead of a board")
    b.add_argument("--preview", metavar="FILE.png", help="IMAGE with the world origin and X/Y axes drawn")
    b.set_defaults(func=run_belt)

    a = csub.add_parser("scale", help="an APPROXIMATE straight-down calibration from a scale (no board)",
                        description="For trying a video before a board is at hand: a camera looking straight "
                        "down, no distortion, with the belt's scale from --mm-per-px or from a part's known "
                        "length (--length-px and --length-mm). The file is marked approximate.")
    a.add_argument("--size", required=True, metavar="WxH", help="image size in pixels, e.g. 1280x720")
    a.add_argument("--mm-per-px", type=float, metavar="S", help="belt millimetres per image pixel")
    a.add_argument("--length-px", type=float, metavar="P", help="a part's length measured in the image (px)")
    a.add_argument("--length-mm", type=float, metavar="M", help="the same part's real length (mm)")
    a.add_argument("--out", required=True, metavar="CALIB", help="calibration file to write (.yaml/.yml/.xml)")
    a.set_defaults(func=run_scale)

    g = csub.add_parser("board", help="a printable board (PNG at true scale) with its settings printed on it",
                        description="Writes the board at true scale on a sheet of paper at --dpi, the DPI "
                        "recorded in the PNG, and the settings to give the calibration commands printed "
                        "under it. A square is a whole number of dots: the sheet says what it measures.")
    _board_args(g, required=False, charuco=True, detector=False)
    g.add_argument("--out", required=True, metavar="FILE.png", help="the sheet to write (PNG)")
    g.add_argument("--dpi", type=int, default=300, help="printer resolution (default %(default)s)")
    g.add_argument("--paper", default="A4", help="A4, A3 or letter (default %(default)s)")
    g.set_defaults(func=run_board)

    r = csub.add_parser("import-ros", help="intrinsics from a ROS camera_info YAML file (then: calibrate belt)",
                        description="Reads a camera_info YAML (as ROS camera_calibration writes it, or "
                        "'calibrate show --format ros'): image size, camera_matrix, distortion_model "
                        "plumb_bob or rational_polynomial, distortion_coefficients. The file written has "
                        "no belt pose yet and no RMS (K was not calibrated here).")
    r.add_argument("camera_info", metavar="CAMERA_INFO.yaml")
    r.add_argument("--out", required=True, metavar="CALIB", help="calibration file to write (.yaml/.yml/.xml)")
    r.set_defaults(func=run_import_ros)

    s = csub.add_parser("show", help="summary of a calibration file (or --format ros: ROS camera_info YAML)")
    s.add_argument("calibration", metavar="CALIB")
    s.add_argument("--format", choices=("text", "ros"), default="text",
                   help="text: a summary (default); ros: the intrinsics as a ROS camera_info YAML on stdout")
    s.set_defaults(func=run_show)


def _board_args(p: argparse.ArgumentParser, required: bool, charuco: bool = False, detector: bool = True) -> None:
    p.add_argument("--pattern", required=required, metavar="COLSxROWS", help="inner corners, e.g. 9x6")
    p.add_argument("--square", required=required, type=float, metavar="MM", help="square size in mm")
    if charuco:
        p.add_argument("--board", metavar="SPEC", help="a ChArUco board instead of --pattern/--square: "
                       "charuco:COLSxROWS:SQUARE_MM:MARKER_MM:DICT (squares, e.g. charuco:11x8:20:14:DICT_5X5_100)")
    if not detector:
        return
    p.add_argument("--detector", choices=DETECTORS, default="auto",
                   help="classic findChessboardCorners + cornerSubPix, sb = findChessboardCornersSB, "
                        "auto = classic then sb (default)")


def _check_out(path: str) -> Path:
    out = Path(path)
    if out.suffix.lower() not in calibfile.SUFFIXES:
        raise BadInput(f"{out}: unsupported extension {out.suffix!r}, expected one of {', '.join(calibfile.SUFFIXES)}")
    check_target("", str(out), "the calibration")
    return out


def _check_preview_file(path: Path) -> None:
    """Before any work (the calibration is written after it): a PNG file OpenCV can write there."""
    if path.suffix.lower() != ".png":
        raise BadInput(f"--preview {path}: expected a .png file name, got {path.suffix or 'no extension'!r}")
    check_target("--preview", str(path), "the preview")


def _check_preview_folder(path: Path) -> None:
    """Before any work: a folder for the previews, or a name for one in a folder that exists."""
    if path.exists() and not path.is_dir():
        raise BadInput(f"--preview {path}: it is a file; expected a folder for the previews")
    if not path.exists():
        check_writable(path, "the previews")
    elif not os.access(path, os.W_OK | os.X_OK):
        raise BadInput(f"--preview {path}: cannot write the previews: the folder is not writable")


def run_intrinsics(args: argparse.Namespace) -> int:
    pattern = board_from_args(args)
    out, report_path = check_intrinsics_args(args)
    images, _ = read_all_same_size(args.images)
    return calibrate_and_write(args.images, images, pattern, out, report_path, args)


def board_from_args(args: argparse.Namespace):
    """A chessboard Pattern from --pattern/--square, or a ChArUco board from --board."""
    if getattr(args, "board", None):
        if args.pattern is not None or args.square is not None:
            raise BadInput("--board: give either --board or --pattern and --square, not both")
        from tracker.calibrate.charuco import parse_board  # noqa: PLC0415 - only for ChArUco

        return parse_board(args.board)
    if args.pattern is None or args.square is None:
        raise BadInput("expected --pattern COLSxROWS and --square MM (a chessboard), or --board SPEC (ChArUco)")
    return parse_pattern(args.pattern, args.square)


def _run_capture(args: argparse.Namespace) -> int:
    from tracker.calibrate.cli_capture import run_capture  # noqa: PLC0415 - only this command

    return run_capture(args)


def check_intrinsics_args(args: argparse.Namespace) -> tuple[Path, Path | None]:
    """The output and report paths, checked before any work (shared with ``calibrate capture``)."""
    out = _check_out(args.out)
    if args.min_views < 3:
        raise BadInput(f"--min-views: expected at least 3, got {args.min_views}")
    report_path = Path(args.report) if args.report else None
    if report_path:
        check_target("--report", str(report_path), "the report")
    if getattr(args, "preview", None):
        _check_preview_folder(Path(args.preview))
    return out, report_path


def calibrate_and_write(paths: list[str], images: list, pattern, out: Path, report_path: Path | None,
                        args: argparse.Namespace) -> int:
    """Calibrate, print the report, refuse or write: what ``calibrate intrinsics`` does with its views."""
    result = calibrate_intrinsics(paths, images, pattern, args.min_views, args.fix_k3, args.detector)
    for line in report.intrinsics_text(result, args.max_rms):
        print(line)
    if getattr(args, "preview", None):
        _write_previews(Path(args.preview), result, images, pattern)
    final = result.final
    if final.rms_px > args.max_rms:
        raise BadInput(f"calibration RMS {final.rms_px:.3f} px exceeds {args.max_rms} px (--max-rms): "
                       f"check the views in the table above; {out} not written")
    calib = calibfile.Calibration(result.image_size[0], result.image_size[1], final.camera_matrix,
                                  final.dist_coeffs, final.rms_px, source=str(out))
    calibfile.save(calib, out)
    print(f"wrote {out}")
    if report_path:
        data = json.dumps(report.intrinsics_json(result, args.max_rms), indent=2).encode()
        report.write_atomic(report_path, data)
        print(f"wrote {report_path}")
    return 0


def _write_previews(folder: Path, result, images: list, pattern) -> None:
    """Each view with the corners found drawn on it, as PNG in ``folder`` (checked before any work):
    written before the calibration is accepted or refused, as they show why."""
    folder.mkdir(exist_ok=True)
    for view, image in zip(result.views, images, strict=True):
        colour = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if view.corners is not None and view.ids is not None:
            cv2.aruco.drawDetectedCornersCharuco(colour, view.corners.astype("float32").reshape(-1, 1, 2),
                                                 view.ids.reshape(-1, 1))
        elif view.corners is not None:
            cv2.drawChessboardCorners(colour, pattern.size, view.corners.astype("float32").reshape(-1, 1, 2), True)
        path = folder / (Path(view.path).stem + ".png")
        if not cv2.imwrite(str(path), colour):
            raise TrackerError(f"{path}: cannot write the preview (disk full?)")
    print(f"wrote {len(result.views)} previews to {folder}")


def run_belt(args: argparse.Namespace) -> int:
    target = _check_out(args.out or args.calibration)
    calib = calibfile.load(args.calibration, require_belt=False)
    if calib.approximate:
        # Its focal length is a guess from a scale and its lens has no distortion: a belt pose fitted
        # through it came out 2518 mm above a belt 700 mm away, and without the mark that keeps parts flat.
        raise BadInput(f"{args.calibration}: its intrinsics are APPROXIMATE (from 'calibrate scale': a focal "
                       f"length guessed from a scale, no lens distortion); a belt pose fitted with them would be "
                       f"wrong: calibrate the intrinsics first ('calibrate intrinsics', 'capture' or 'import-ros')")
    preview = Path(args.preview) if args.preview else None
    if preview:
        _check_preview_file(preview)
    if preview and not args.image:
        raise BadInput("--preview needs IMAGE (the view to draw on)")
    image = read_grey(args.image) if args.image else None
    names = None
    if args.points:
        px, mm = read_pairs(args.points)
        if image is not None:
            h, w = image.shape[:2]
            if (w, h) != calib.size:
                raise BadInput(f"{args.image}: image is {w}x{h}, calibration {calib.source} is for "
                               f"{calib.image_width}x{calib.image_height}")
        result = belt_from_points(calib, px, mm, args.points)
        names = [str(n + 1) for n in range(len(px))]
        axis_mm = float(max(mm.max(axis=0) - mm.min(axis=0)) / 2)
    else:
        if image is None or (args.board is None and (args.pattern is None or args.square is None)):
            raise BadInput("calibrate belt: expected IMAGE with --pattern and --square (or --board), "
                           "or --points PAIRS.csv")
        pattern = board_from_args(args)
        result = belt_from_board(calib, image, args.image, pattern, args.detector)
        axis_mm = 2 * pattern.square_mm
    for line in report.belt_text(result, names):
        print(line)
    if preview:
        # Before the calibration: a preview that cannot be written leaves the calibration as it was.
        ok, png = cv2.imencode(".png", draw_preview(image, result, axis_mm))
        if not ok:
            raise TrackerError(f"{preview}: cannot encode the preview")
        report.write_atomic(preview, png.tobytes())
        print(f"wrote {preview}")
    calibfile.save(result.calibration, target)
    print(f"wrote {target}" + ("" if args.out else " (updated in place)"))
    return 0


def run_scale(args: argparse.Namespace) -> int:
    from tracker.calibrate.approximate import nadir_calibration  # noqa: PLC0415 - only this command

    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise BadInput(f"--size: expected WIDTHxHEIGHT in pixels, e.g. 1280x720, got {args.size!r}") from None
    by_length = args.length_px is not None or args.length_mm is not None
    if (args.mm_per_px is None) == (not by_length) or (by_length and None in (args.length_px, args.length_mm)):
        raise BadInput("scale: give --mm-per-px S, or both --length-px P and --length-mm M")
    if by_length:
        if not (args.length_px > 0 and args.length_mm > 0):
            raise BadInput(f"--length-px/--length-mm: expected positive lengths, got {args.length_px} px, "
                           f"{args.length_mm} mm")
        mm_per_px = args.length_mm / args.length_px
    else:
        mm_per_px = args.mm_per_px
    out = _check_out(args.out)
    calib = nadir_calibration(width, height, mm_per_px)
    calibfile.save(calib, out)
    print(f"tracker: wrote {out}: APPROXIMATE, {mm_per_px:.4g} mm/px, straight down, no distortion")
    return 0


def run_board(args: argparse.Namespace) -> int:
    from tracker.calibrate.printable import make_sheet, png_bytes  # noqa: PLC0415 - only this command

    board = board_from_args(args)
    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise BadInput(f"{out}: expected a .png file")
    check_target("--out", str(out), "the board")
    sheet = make_sheet(board, args.dpi, args.paper)
    report.write_atomic(out, png_bytes(sheet))
    print(f"wrote {out}: {args.paper} at {args.dpi} dpi; one square prints {sheet.square_mm:.3f} mm "
          f"(print at 100 %, measure it, and give that size to the calibration commands)")
    return 0


def run_import_ros(args: argparse.Namespace) -> int:
    from tracker.calibrate.ros import read_camera_info  # noqa: PLC0415 - only this command

    out = _check_out(args.out)
    calib = read_camera_info(args.camera_info)
    calibfile.save(calib, out)
    k = calib.camera_matrix
    print(f"tracker: wrote {out}: intrinsics from {args.camera_info} ({calib.image_width}x{calib.image_height}, "
          f"fx {k[0, 0]:.2f} fy {k[1, 1]:.2f} px, {calib.dist_coeffs.size} distortion coefficients); "
          f"next: tracker calibrate belt IMAGE --calibration {out} ...")
    return 0


def run_show(args: argparse.Namespace) -> int:
    calib = calibfile.load(args.calibration, require_belt=False)
    if args.format == "ros":
        from tracker.calibrate.ros import camera_info_yaml  # noqa: PLC0415 - only this format

        print(camera_info_yaml(calib), end="")
        return 0
    for line in report.show_text(calib):
        print(line)
    return 0


__all__ = ["register"]
