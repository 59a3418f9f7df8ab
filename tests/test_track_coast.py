"""A part hidden for a few frames (an arm passing over it) keeps its id; frames since last measured are counted."""

from __future__ import annotations

import dataclasses

import pytest

from tracker.config import TrackConfig, TrackerConfig
from tracker.pipeline import Pipeline
from tracker.scenes import resized
from tracker.synthetic import CameraSpec, PartSpec, Renderer, SceneSpec

FPS = 30.0
HIDDEN = range(40, 52)  # 12 frames = 0.4 s: part A is covered (rendered without it)


def _scene(parts: tuple[PartSpec, ...]) -> SceneSpec:
    scene = SceneSpec(CameraSpec(), parts, fps=FPS, n_frames=70, supersample=2, blur_samples=1)
    return resized(scene, 320, 240)


A = PartSpec(80, 50, 0, -480, -90, 20, 300, 0)
B = PartSpec(70, 40, 0, -560, 110, -30, 300, 0, intensity=180)


def _track(n_frames: int, config: TrackerConfig | None = None) -> tuple[list, list]:
    both, only_b = Renderer(_scene((A, B))), Renderer(_scene((B,)))
    pipeline = Pipeline(both.calibration, config)
    results, truths = [], []
    for i in range(n_frames):
        image, truth = both.render(i)
        if i in HIDDEN:
            image = only_b.render(i)[0]
        results.append(pipeline.process(i, image, both.scene.t_ns(i)))
        truths.append(truth)
    return results, truths


@pytest.fixture(scope="module")
def run():
    return _track(70)


def _nearest(result, x: float, y: float):
    return min(result.objects, key=lambda o: (o.x_mm - x) ** 2 + (o.y_mm - y) ** 2)


def test_hidden_part_keeps_its_id_and_reports_its_age(run):
    results, truths = run
    before = HIDDEN.start - 1
    ta = truths[before]["objects"][0]
    a_id = _nearest(results[before], ta["x_mm"], ta["y_mm"]).id
    assert results[before].objects and all(o.age_frames == 0 for o in results[before].objects if o.id == a_id)
    for k, i in enumerate(HIDDEN, start=1):
        a = next((o for o in results[i].objects if o.id == a_id), None)
        assert a is not None, f"frame {i}: the hidden part's track ended"
        assert not a.measured and a.age_frames == k
        t = truths[i]["objects"][0]
        assert abs(a.x_mm - t["x_mm"]) < 5.0, "coasting follows the belt"
    after = HIDDEN.stop + 2
    t = truths[after]["objects"][0]
    back = _nearest(results[after], t["x_mm"], t["y_mm"])
    assert back.id == a_id and back.measured and back.age_frames == 0
    assert abs(back.x_mm - t["x_mm"]) < 1.0 and abs(back.y_mm - t["y_mm"]) < 1.0
    # No other id was ever given to part A or B: two parts, two ids.
    assert {o.id for r in results for o in r.objects} == {a_id, _nearest(results[after], *(
        truths[after]["objects"][1][k] for k in ("x_mm", "y_mm"))).id}


def test_a_track_still_ends_when_hidden_longer_than_the_coast_time():
    # The same scene with the coast time shorter than the 0.4 s hiding: A comes back under a new id.
    cfg = dataclasses.replace(TrackerConfig(), track=TrackConfig(max_coast_s=0.2))
    results, _ = _track(HIDDEN.stop + 3, cfg)
    assert len({o.id for r in results for o in r.objects}) == 3


def test_a_blob_whose_view_tells_another_size_than_its_lent_one_is_not_the_part():
    """A box fitted with its track's size lent is pulled to that size: a piece of the part (noise cut
    its blob in two at the edge of a faint side) was fitted at the whole part's 76 mm, 20 mm off along
    the belt, and broke the track's velocity. The size a piece's view tells on its own (own_size_mm)
    shows it: the track coasts through that frame, as through a partly hidden part's, and keeps its
    pose."""
    from tracker.geometry import Rect
    from tracker.measure import Measurement
    from tracker.track import Tracker

    tracker = Tracker(TrackConfig())
    step_ns, speed_mm_s = round(1e9 / FPS), 300.0

    def blob(i: int, dx_mm: float = 0.0, own: tuple[float, float] | None = (76.0, 36.0),
             piece: bool = False) -> Measurement:
        x = -200.0 + speed_mm_s * i / FPS + dx_mm
        return Measurement(Rect(x, 0.0, 0.0, 76.0, 36.0), False, (0, 0, 1, 1), (0.0, 0.0), 200, piece=piece,
                           own_size_mm=own)

    for i in range(15):
        (part,) = tracker.step([blob(i)], i * step_ns)
    assert part.measured
    # The piece: 20 mm ahead, fitted at the lent 76 mm, its own view 52 mm long.
    (part,) = tracker.step([blob(15, 20.0, own=(52.0, 36.0), piece=True)], 15 * step_ns)
    assert not part.measured and abs(part.x_mm - (-200.0 + speed_mm_s * 15 / FPS)) < 0.5, part
    (part,) = tracker.step([blob(16)], 16 * step_ns)
    assert part.measured and abs(part.vx_mm_s - speed_mm_s) < 5.0, part


@pytest.mark.parametrize("dy_mm, measured", [(11.0, False), (1.0, True)])
def test_a_piece_aside_from_its_part_is_not_the_part_even_at_its_size(dy_mm, measured):
    """A piece whose own view tells the part's size too (the side its cut left open is held by the lent
    size alone: random scene 37 under a lamp, a faint face's noise cut its blob in three, the largest
    piece fitted at the part's size 11 mm aside) lies off the part's predicted centre: the track coasts
    through it and keeps its velocity. A piece where the part is predicted (cut from a blob of two
    touching parts) is the part."""
    from tracker.geometry import Rect
    from tracker.measure import Measurement
    from tracker.track import Tracker

    tracker = Tracker(TrackConfig())
    step_ns, speed_mm_s = round(1e9 / FPS), 300.0

    def blob(i: int, dy: float = 0.0, piece: bool = False) -> Measurement:
        x = -200.0 + speed_mm_s * i / FPS
        return Measurement(Rect(x, dy, 0.0, 76.0, 36.0), False, (0, 0, 1, 1), (0.0, 0.0), 200, piece=piece,
                           own_size_mm=(76.0, 36.0))

    for i in range(15):
        (part,) = tracker.step([blob(i)], i * step_ns)
    (part,) = tracker.step([blob(15, dy_mm, piece=True)], 15 * step_ns)
    assert part.measured == measured, part
    assert abs(part.y_mm - (dy_mm if measured else 0.0)) < 0.5, part
    (part,) = tracker.step([blob(16)], 16 * step_ns)
    assert part.measured and abs(part.vy_mm_s) < (100.0 if measured else 5.0), part


@pytest.mark.parametrize("dy_mm, grown_mm, measured", [(10.0, 4.5, False), (10.0, 0.0, True), (1.0, 4.5, True)])
def test_a_whole_blob_aside_from_its_part_and_of_another_size_is_not_the_part(dy_mm, grown_mm, measured):
    """A whole blob 10 mm off the part's predicted centre and 4.5 mm larger is not a view of it, though 4.5 mm
    is within the size check's fraction of the part (random scene 42 under a lamp: a 60 mm box's dim
    face, partly segmented, made such blobs, and one taken let the next, 7 mm larger, in: the part posed
    6-10 mm off for six frames). The track coasts through it. The part pushed 10 mm aside at its own size
    is followed, and a blob 4.5 mm larger where the part is predicted is the part (its size check decides)."""
    from tracker.geometry import Rect
    from tracker.measure import Measurement
    from tracker.track import Tracker

    tracker = Tracker(TrackConfig())
    step_ns, speed_mm_s = round(1e9 / FPS), 300.0

    def blob(i: int, dy: float = 0.0, grown: float = 0.0) -> Measurement:
        x = -200.0 + speed_mm_s * i / FPS
        return Measurement(Rect(x, dy, 0.0, 80.0 + grown, 60.0 + grown), False, (0, 0, 1, 1), (0.0, 0.0), 200)

    for i in range(15):
        (part,) = tracker.step([blob(i)], i * step_ns)
    (part,) = tracker.step([blob(15, dy_mm, grown_mm)], 15 * step_ns)
    assert part.measured == measured, part
    assert abs(part.y_mm - (dy_mm if measured else 0.0)) < 0.5, part
    (part,) = tracker.step([blob(16, dy_mm if measured else 0.0)], 16 * step_ns)
    assert part.measured and abs(part.vy_mm_s) < (400.0 if measured else 5.0), part
