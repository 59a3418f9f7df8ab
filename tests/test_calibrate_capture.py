"""tracker calibrate capture on a rendered video of a board moving and tilting in front of a known camera:
sharp views held still (each shown twice: duplicates), a slightly blurred frame at every stop, and
motion-blurred frames between the stops. What is kept, when it stops, and the camera it finds."""

from __future__ import annotations

import functools
import re

import cv2
import numpy as np
import pytest

from tracker import calibration as calib_io
from tracker.calibrate.board import Pattern
from tracker.calibrate.capture import CaptureSettings, ViewSelector
from tracker.calibrate.synthetic_board import BoardLook, BoardRenderer, look_at_pose
from tracker.cli import main
from tracker.synthetic import STRONG_DISTORTION, CameraSpec

CAMERA = CameraSpec(width=480, height=360, focal_px=420.0, principal_offset_px=(6.0, -4.0),
                    dist_coeffs=STRONG_DISTORTION)
PATTERN = Pattern(9, 6, 20.0)
STOPS = 16


@functools.cache
def _renderer() -> BoardRenderer:
    c = CAMERA.calibration()
    return BoardRenderer(c.camera_matrix, c.dist_coeffs, c.size, PATTERN, BoardLook(supersample=3))


def _stop(i: int) -> tuple:
    """Board placement i: (centre in the camera frame, tilt, tilt direction, spin), spread over the image."""
    rng = np.random.default_rng(100 + i)
    z = 380 + 60 * rng.random()
    ang = 2 * np.pi * i / STOPS
    rad = 0.0 if i == 0 else (0.2 if i % 2 else 0.33)
    centre = np.array([z * rad * np.cos(ang) * 480 / 420, z * rad * np.sin(ang) * 360 / 420, z])
    return centre, 20 + 25 * ((i * 7) % STOPS) / (STOPS - 1), (i * 137.0) % 360, rng.uniform(-25, 25)


def _render(a: tuple, b: tuple, s: float, seed: int) -> np.ndarray:
    """The board a fraction s of the way from placement a to placement b."""
    centre = (1 - s) * a[0] + s * b[0]
    tilt, direction, spin = ((1 - s) * a[k] + s * b[k] for k in (1, 2, 3))
    return _renderer().render(*look_at_pose(centre, tilt, direction, spin, PATTERN), seed=seed)


def _blurred(a: tuple, b: tuple, s0: float, s1: float, seed: int, samples: int = 3) -> np.ndarray:
    frames = [_render(a, b, s, seed).astype(np.float64) for s in np.linspace(s0, s1, samples)]
    return np.clip(np.rint(np.mean(frames, axis=0)), 0, 255).astype(np.uint8)


@pytest.fixture(scope="session")
def video(tmp_path_factory):
    """frames/%05d.png, and for each frame whether it is sharp (a still board) or blurred."""
    folder = tmp_path_factory.mktemp("capture") / "frames"
    folder.mkdir()
    frames, sharp = [], []
    stops = [_stop(i) for i in range(STOPS)]
    for i, here in enumerate(stops):
        nxt = stops[(i + 1) % STOPS]
        still = _render(here, nxt, 0.0, seed=i)
        frames += [still, still.copy()]  # held still: the same frame twice
        sharp += [True, True]
        frames.append(_blurred(here, nxt, 0.0, 0.05, seed=i))  # starting to move: slightly blurred
        frames.append(_blurred(here, nxt, 0.3, 0.6, seed=i))  # on its way: strongly blurred
        sharp += [False, False]
    for k, f in enumerate(frames):
        cv2.imwrite(str(folder / f"{k:05d}.png"), f)
    return folder, frames, sharp


@pytest.fixture(scope="session")
def captured(video, tmp_path_factory):
    folder, _, _ = video
    out = tmp_path_factory.mktemp("capture_out") / "cell.yaml"
    import contextlib
    import io

    log = io.StringIO()
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        code = main(["calibrate", "capture", "--source", str(folder / "%05d.png"), "--pattern", "9x6",
                     "--square", "20", "--out", str(out), "--report", str(out.with_suffix(".json"))])
    return code, out, log.getvalue()


def test_capture_keeps_sharp_new_views_and_finds_the_true_camera(video, captured):
    _, frames, sharp = video
    code, out, log = captured
    assert code == 0, log
    kept = sorted(out.with_suffix(".views").glob("view_*.png"))
    assert 12 <= len(kept) <= 16, log
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in kept]
    for image in images:
        same = [k for k, f in enumerate(frames) if np.array_equal(f, image)]
        assert same and all(sharp[k] for k in same), "only frames of a still board are kept"
    # Never the same view twice (each still frame was shown twice).
    assert len({im.tobytes() for im in images}) == len(images)
    m = re.search(r"capture: (\w[\w -]*): (\d+) frames, (\d+) views kept", log)
    assert m and m.group(1) == "enough views", log  # it stopped itself before the video ended
    assert int(m.group(2)) < len(frames)
    assert re.search(r"frames not kept: .*\d+ blurred", log) and "like a kept view" in log, log
    true = CAMERA.calibration().camera_matrix
    got = calib_io.load(out, require_belt=False).camera_matrix
    assert abs(got[0, 0] / true[0, 0] - 1) < 0.003 and abs(got[1, 1] / true[1, 1] - 1) < 0.003, got
    assert abs(got[0, 2] - true[0, 2]) < 2.0 and abs(got[1, 2] - true[1, 2]) < 2.0, got


def test_the_saved_views_give_the_same_calibration(captured, tmp_path, capsys):
    _, out, log = captured
    command = re.search(r"the same result again: tracker (calibrate intrinsics .*)", log).group(1).split()
    views = sorted(str(p) for p in out.with_suffix(".views").glob("view_*.png"))
    again = tmp_path / "again.yaml"
    args = [w for w in command[2:] if "*" not in w]
    args[args.index("--out") + 1] = str(again)
    assert main(["calibrate", "intrinsics", *views, *args]) == 0
    assert np.allclose(calib_io.load(again, require_belt=False).camera_matrix,
                       calib_io.load(out, require_belt=False).camera_matrix, rtol=1e-9)


def test_the_views_folder_of_another_session_is_never_overwritten(captured, video, capsys):
    folder, _, _ = video
    _, out, _ = captured
    before = sorted(p.name for p in out.with_suffix(".views").iterdir())
    code = main(["calibrate", "capture", "--source", str(folder / "%05d.png"), "--pattern", "9x6",
                 "--square", "20", "--out", str(out)])
    assert code == 2
    assert "exists and is not empty" in capsys.readouterr().err
    assert sorted(p.name for p in out.with_suffix(".views").iterdir()) == before


def test_a_video_without_the_board_is_exit_2(tmp_path, capsys):
    folder = tmp_path / "empty"
    folder.mkdir()
    for k in range(5):
        cv2.imwrite(str(folder / f"{k:05d}.png"), np.full((120, 160), 100, np.uint8))
    code = main(["calibrate", "capture", "--source", str(folder / "%05d.png"), "--pattern", "9x6",
                 "--square", "20", "--out", str(tmp_path / "c.yaml")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "only 0 good views" in err[-1], err
    assert not (tmp_path / "c.yaml").exists()


def test_ctrl_c_ends_the_capture_and_calibrates_what_was_kept(video, tmp_path, monkeypatch, capsys):
    """A camera that the user stops with Ctrl-C after 30 frames: the views kept so far are calibrated."""
    folder, frames, _ = video
    from tracker import cli_run
    from tracker.sources import Frame, FrameSource

    class Interrupted(FrameSource):
        name = "camera 0"

        def __iter__(self):
            for k, f in enumerate(frames[:30]):
                yield Frame(k, k * 33_000_000, f)
            raise KeyboardInterrupt

    monkeypatch.setattr(cli_run, "open_source", lambda spec, fps=None: Interrupted())
    out = tmp_path / "c.yaml"
    code = main(["calibrate", "capture", "--source", "0", "--pattern", "9x6", "--square", "20",
                 "--out", str(out), "--min-views", "5"])
    log = capsys.readouterr()
    assert code == 0, log
    assert "capture: Ctrl-C: 30 frames" in log.out
    assert len(list((tmp_path / "c.views").glob("*.png"))) >= 5 and out.exists()


def test_the_selector_wants_coverage_and_tilts_not_just_a_count():
    """Twenty views of one placement (image centre, one tilt): never enough, whatever their number."""
    settings = CaptureSettings(target_views=5, max_views=40, min_shift=0.0, min_scale_change=0.0,
                               min_tilt_change_deg=0.0)
    c = CAMERA.calibration()
    selector = ViewSelector(PATTERN, c.size, settings)
    image = _render(_stop(0), _stop(0), 0.0, seed=0)
    corners = cv2.findChessboardCorners(image, PATTERN.size)[1].reshape(-1, 2).astype(np.float64)
    for _ in range(20):
        assert selector.offer(image, corners)
    assert selector.progress.kept == 20 and not selector.enough()
    assert selector.progress.cells < settings.min_cells


def test_the_capture_shows_its_progress_on_the_live_page(video, tmp_path, monkeypatch, capsys):
    """--web: while capturing, the page's state.json carries the progress and frame.jpg the corners."""
    import json
    import socket
    import urllib.request

    folder, frames, _ = video
    from tracker import cli_run
    from tracker.sources import Frame, FrameSource

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    seen = {}

    class Camera(FrameSource):
        name = "camera 0"

        def __iter__(self):
            for k, f in enumerate(frames[:24]):
                if k == 20:  # frames 0-19 were offered: look at the page as a user would
                    base = f"http://127.0.0.1:{port}/"
                    seen["state"] = json.loads(urllib.request.urlopen(base + "state.json", timeout=5).read())
                    seen["jpeg"] = urllib.request.urlopen(base + "frame.jpg", timeout=5).read()
                yield Frame(k, k * 33_000_000, f)

    monkeypatch.setattr(cli_run, "open_source", lambda spec, fps=None: Camera())
    code = main(["calibrate", "capture", "--source", "0", "--pattern", "9x6", "--square", "20",
                 "--out", str(tmp_path / "c.yaml"), "--min-views", "3", "--web", f"127.0.0.1:{port}"])
    assert code == 0, capsys.readouterr()
    cap = seen["state"]["capture"]
    assert seen["state"]["frame"] == 19 and cap["views"] == 5 and cap["cells"] > 0, seen["state"]
    assert "views" in seen["state"]["sinks"][0]
    image = cv2.imdecode(np.frombuffer(seen["jpeg"], np.uint8), cv2.IMREAD_COLOR)
    assert image.shape[:2] == frames[0].shape
    # The frame is grey: the coverage grid's lines (green) are the overlay.
    line = image[:, image.shape[1] // 4].astype(int)
    assert np.mean(line[:, 1] - line[:, 2]) > 10  # grey frames give 0 (JPEG rounding: +-2)
