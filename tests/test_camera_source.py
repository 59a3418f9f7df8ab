"""Live cameras, with a fake capture device (a physical camera cannot exist here).

The loop must always get the newest frame (never a stale buffered one), count
the frames it could not take as overruns, and report a dead camera clearly.
"""

import threading
import time

import numpy as np
import pytest

from tracker import sources
from tracker.cli import main
from tracker.errors import SourceError, SourceLost
from tracker.sources import CameraSource


class FakeCapture:
    """Delivers numbered frames (the number is in pixel [0, 0]) as fast as asked, or dies."""

    def __init__(self, index, frames=10_000, opened=True, period_s=0.0005, stamp=None):
        self.frames, self.opened, self.period_s = frames, opened, period_s
        self.delivered = 0
        self.lock = threading.Lock()
        # What get(CAP_PROP_POS_MSEC) says of the frame last read (arrival in monotonic ns -> ms); None:
        # 0, as OpenCV's backends that know nothing of it.
        self.stamp = stamp
        self.arrivals: list[int] = []
        self.stamped: list[float] = []

    def isOpened(self):  # noqa: N802 - OpenCV's name
        return self.opened

    def set(self, *_):
        return True

    def read(self):
        time.sleep(self.period_s)  # the camera's frame interval, not a wait for a server
        with self.lock:
            if self.delivered >= self.frames:
                return False, None
            image = np.zeros((48, 64), np.uint8)
            image[0, 0] = self.delivered % 256
            image[0, 1] = self.delivered // 256
            self.delivered += 1
            now = time.monotonic_ns()
            self.arrivals.append(now)
            self.stamped.append(0.0 if self.stamp is None else self.stamp(now))
        return True, image

    def get(self, prop):
        assert prop == sources.cv2.CAP_PROP_POS_MSEC
        with self.lock:
            return self.stamped[-1] if self.stamped else 0.0

    def release(self):
        pass


def _fake(monkeypatch, **kw):
    made = {}

    def factory(index):
        made["cap"] = FakeCapture(index, **kw)
        return made["cap"]

    monkeypatch.setattr(sources.cv2, "VideoCapture", factory)
    return made


def test_slow_loop_gets_the_newest_frames_and_counts_overruns(monkeypatch):
    made = _fake(monkeypatch, frames=400)
    cam = CameraSource(0)
    taken = []
    with pytest.raises(SourceLost):
        for frame in cam:
            taken.append(int(frame.image[0, 0]) + 256 * int(frame.image[0, 1]))
            time.sleep(0.005)  # a loop 10x slower than the camera
    cam.close()
    delivered = made["cap"].delivered
    assert delivered == 400
    assert taken == sorted(set(taken)), "frames come in order, none twice"
    assert len(taken) < delivered / 3, "the loop was slower: it must not see every buffered frame"
    # Every frame the camera delivered was either taken by the loop or replaced unseen (an overrun).
    assert cam.overruns == delivered - len(taken)
    assert max(np.diff(taken)) > 2


def test_camera_that_stops_delivering_is_lost(monkeypatch):
    _fake(monkeypatch, frames=5)
    cam = CameraSource(0)
    with pytest.raises(SourceLost, match="camera 0: stopped delivering frames"):
        for _ in cam:
            pass
    cam.close()


def test_camera_that_cannot_open_is_bad_input(monkeypatch, capsys, tmp_path):
    _fake(monkeypatch, opened=False)
    with pytest.raises(SourceError, match="camera 3: cannot open"):
        CameraSource(3)
    from tracker import calibration as calib_io
    from tracker.synthetic import CameraSpec

    calib = tmp_path / "c.yaml"
    calib_io.save(CameraSpec().calibration(), calib)
    assert main(["run", "--source", "3", "--calibration", str(calib), "--no-plc", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "camera 3: cannot open" in err and len(err.strip().splitlines()) == 1


def test_dead_camera_mid_run_ends_the_run_with_one_line(monkeypatch, capsys, tmp_path):
    from tracker import calibration as calib_io
    from tracker.synthetic import CameraSpec

    _fake(monkeypatch, frames=30)
    calib = tmp_path / "c.yaml"
    calib_io.save(CameraSpec(width=64, height=48, focal_px=56.0).calibration(), calib)
    code = main(["run", "--source", "0", "--calibration", str(calib), "--no-plc", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1
    assert "camera 0: stopped delivering frames" in err and "Traceback" not in err


def test_overruns_reach_the_health_word_and_status_line(monkeypatch):
    from tracker.health import FAULT_OVERRUN, Health
    from tracker.pipeline import Pipeline
    from tracker.runner import Runner
    from tracker.synthetic import CameraSpec

    _fake(monkeypatch, frames=2000)

    class SlowSink:
        def submit(self, frame, result):
            time.sleep(0.004)  # stands in for a loop slower than the camera

        def status(self):
            return ""

        def close(self):
            pass

    class Lines:
        def __init__(self):
            self.lines = []

        def due(self):
            return True

        def show(self, text, force=False):
            self.lines.append(text)

        def end(self):
            pass

    health, status = Health(), Lines()
    calib = CameraSpec(width=64, height=48, focal_px=56.0).calibration()
    runner = Runner(CameraSource(0), Pipeline(calib), [SlowSink()], health, status, max_frames=20)
    summary = runner.run()
    assert summary.frames == 20
    assert summary.overruns > 20 and health.overruns == summary.overruns
    assert health.fault == FAULT_OVERRUN
    assert any("overruns" in line for line in status.lines)


def test_the_overrun_fault_clears_once_the_loop_keeps_up_again(monkeypatch):
    """Fault 4 says frames are being dropped now: a loop that fell behind for a few frames and keeps up
    again clears it after the hold (a PLC would otherwise see the cell faulty for good after a single
    dropped frame); the overruns stay counted."""
    from tracker.health import FAULT_NONE, FAULT_OVERRUN, Health
    from tracker.pipeline import Pipeline
    from tracker.runner import Runner
    from tracker.synthetic import CameraSpec

    _fake(monkeypatch, frames=2000, period_s=0.01)
    health = Health()
    faults = []

    class SlowThenFastSink:
        def submit(self, frame, result):
            faults.append(health.fault)
            if len(faults) <= 5:
                time.sleep(0.035)  # behind a 100 fps camera for five frames

        def status(self):
            return ""

        def close(self):
            pass

    calib = CameraSpec(width=64, height=48, focal_px=56.0).calibration()
    runner = Runner(CameraSource(0), Pipeline(calib), [SlowThenFastSink()], health, max_frames=60,
                    overrun_hold_s=0.1)
    summary = runner.run()
    assert summary.overruns > 0 and health.overruns == summary.overruns
    set_at = faults.index(FAULT_OVERRUN)
    assert set_at <= 6, faults
    # Cleared once no frame has been dropped for the hold (a busy machine may drop one more later:
    # it is set again, and clears again).
    assert FAULT_NONE in faults[set_at:], faults


@pytest.mark.parametrize(("stamp", "lag_ms"), [
    (lambda now: now / 1e6 - 40.0, 40.0),  # V4L2: the driver's monotonic stamp, 40 ms before arrival
    (None, 0.0),  # a backend that stamps nothing
    (lambda now: 1234.5, 0.0),  # a stream position, not a time on our clock
    (lambda now: now / 1e6 + 100.0, 0.0),  # in the future: not believed
    (lambda now: now / 1e6 - 5000.0, 0.0),  # too long ago to be this frame's
])
def test_a_cameras_frame_carries_its_capture_time_where_the_driver_stamps_it(monkeypatch, stamp, lag_ms):
    # A USB camera's frame arrives tens of ms after it was exposed: 12 mm of travel at 300 mm/s in the
    # PLC's extrapolation of "where the part is now" when t_capture_ms is its arrival.
    made = _fake(monkeypatch, frames=20, period_s=0.002, stamp=stamp)
    cam = CameraSource(0)
    frames = []
    try:
        for frame in cam:
            frames.append(frame)
            if len(frames) == 5:
                break
    finally:
        cam.close()
    arrivals = np.array(made["cap"].arrivals)
    for frame in frames:
        assert frame.arrival_ns == frame.t_ns
        # Its capture time is that of a frame read: the stamp's (to the microsecond), or (no stamp to
        # believe) its arrival, read just after the capture returned it.
        after = (frame.t_ns + lag_ms * 1e6) - arrivals
        if lag_ms:
            assert np.min(np.abs(after)) < 0.01e6
        else:
            assert np.any((after >= 0) & (after < 20e6)), after / 1e6
    assert [f.t_ns for f in frames] == sorted({f.t_ns for f in frames})
