"""The renderer itself: its edges are where OpenCV's own projection says they are, and its faces cover
each pixel as much as their exact projected polygons do."""

import math

import cv2
import numpy as np
import pytest
from conftest import BOX_SUPERSAMPLE

from tracker.synthetic import STRONG_DISTORTION, CameraSpec, PartSpec, Renderer, SceneSpec


def _edge_offsets(scene: SceneSpec, part: PartSpec) -> np.ndarray:
    """Signed distance (px) from each projected true edge point to the rendered 50 % crossing."""
    renderer = Renderer(scene)
    image, _ = renderer.render(0)
    calib = renderer.calibration
    level = part.intensity
    belt = renderer._background  # noise-free scene: image = belt + coverage * (part - belt)
    cover = (image.astype(np.float64) - belt) / (level - belt)
    x, y, a = part.pose(0.0)
    c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
    hl, hw = part.length_mm / 2, part.width_mm / 2
    corners = [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)]
    offsets = []
    for (u0, v0), (u1, v1) in zip(corners, corners[1:] + corners[:1], strict=True):
        # Points along the middle of each side, their outward normal, both in world mm.
        f = np.linspace(0.15, 0.85, 25)[:, None]
        local = np.array([u0, v0]) * (1 - f) + np.array([u1, v1]) * f
        normal = np.array([v1 - v0, -(u1 - u0)], dtype=np.float64)
        normal /= np.linalg.norm(normal)
        for sign in (1,):
            world = np.column_stack([x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]])
            n_world = np.array([c * normal[0] - s * normal[1], s * normal[0] + c * normal[1]]) * sign
            pts3 = lambda w: np.column_stack([w, np.zeros(len(w))])  # noqa: E731
            on, out = (cv2.projectPoints(pts3(w), calib.belt_rvec, calib.belt_tvec, calib.camera_matrix,
                                         calib.dist_coeffs)[0].reshape(-1, 2) for w in (world, world + n_world))
            direction = (out - on) / np.linalg.norm(out - on, axis=1, keepdims=True)
            for p, d in zip(on, direction, strict=True):
                ts = np.linspace(-3, 3, 61)
                samples = p + ts[:, None] * d
                prof = cv2.remap(cover.astype(np.float32), samples[:, 0:1].astype(np.float32),
                                 samples[:, 1:2].astype(np.float32), cv2.INTER_LINEAR).ravel()
                # Outward the coverage falls from 1 to 0; whatever the (symmetric) blur of
                # pixel area and interpolation, its integral over the window places the edge.
                integral = float(np.sum((prof[1:] + prof[:-1]) / 2) * (ts[1] - ts[0]))
                offsets.append(integral + ts[0])
    return np.array(offsets)


@pytest.mark.parametrize(
    "camera",
    [CameraSpec(), CameraSpec(dist_coeffs=STRONG_DISTORTION, tilt_deg=20, yaw_deg=30)],
    ids=["nadir", "tilt20-strong-distortion"],
)
def test_rendered_edges_lie_on_projected_true_edges(camera):
    # Large, static, noise-free part away from the centre (where distortion bends its edges).
    part = PartSpec(160, 110, 0, 120, 60, 17)
    scene = SceneSpec(camera, (part,), n_frames=1, noise_sigma=0, blur_samples=1)
    offsets = _edge_offsets(scene, part)
    assert len(offsets) == 100
    assert np.max(np.abs(offsets)) < 0.1, f"max edge offset {np.max(np.abs(offsets)):.3f} px"


def test_truth_has_the_pose_stream_shape_and_visibility():
    part = PartSpec(50, 80, 0, -200, 0, 10, 300, 0)  # width > length: truth swaps them
    scene = SceneSpec(CameraSpec(), (part,), n_frames=1, noise_sigma=0)
    _, truth = Renderer(scene).render(0)
    (obj,) = truth["objects"]
    assert obj["length_mm"] == 80 and obj["width_mm"] == 50
    assert obj["angle_deg"] == pytest.approx(-80.0)
    corners = np.array(obj["corners_mm"])
    x, y = corners[:, 0], corners[:, 1]
    assert 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) == pytest.approx(80 * 50)
    assert obj["visible_px"] > 0 and obj["border_px"] > 0
    far = SceneSpec(CameraSpec(), (PartSpec(50, 80, 0, -2000, 0),), n_frames=1)
    assert Renderer(far).render(0)[1]["objects"][0]["visible_px"] == 0


def test_motion_blur_noise_and_flicker_are_deterministic_and_present():
    part = PartSpec(80, 50, 0, 0, 0, 0, 600, 0)
    base = SceneSpec(CameraSpec(), (part,), n_frames=2, noise_sigma=0, exposure_s=0.01, flicker=0)
    sharp = SceneSpec(CameraSpec(), (part,), n_frames=2, noise_sigma=0, exposure_s=1e-6, flicker=0)
    blurred, _ = Renderer(base).render(1)
    crisp, _ = Renderer(sharp).render(1)
    # 6 mm of travel during the exposure: the leading/trailing edges are spread over more pixels.
    partial = lambda img: int(((img > 70) & (img < 190)).sum())  # noqa: E731
    assert partial(blurred) > 2 * partial(crisp)
    noisy = SceneSpec(CameraSpec(), (), n_frames=3, noise_sigma=2.0, flicker=0.03, seed=4)
    a, b = Renderer(noisy).render(2)[0], Renderer(noisy).render(2)[0]
    assert np.array_equal(a, b)
    means = [Renderer(noisy).render(i)[0].mean() for i in range(3)]
    assert np.ptp(means) > 0.2  # flicker changes the overall level from frame to frame


def _area_in_pixel(polygon: np.ndarray, col: int, row: int) -> float:
    """The area of a convex polygon (image px) inside pixel (col, row), whose centre is (col, row)."""
    points = [tuple(p) for p in polygon]
    for axis, bound, keep_above in ((0, col - 0.5, True), (0, col + 0.5, False), (1, row - 0.5, True),
                                    (1, row + 0.5, False)):
        inside = [(p[axis] >= bound) == keep_above or p[axis] == bound for p in points]
        clipped = []
        for k, b in enumerate(points):
            a = points[k - 1]
            if inside[k - 1] != inside[k]:
                f = (bound - a[axis]) / (b[axis] - a[axis])
                clipped.append((a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])))
            if inside[k]:
                clipped.append(b)
        points = clipped
        if len(points) < 3:
            return 0.0
    x, y = np.array(points).T
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


@pytest.mark.parametrize("angle_deg", [3, 17, 31, 44, 58, 72])
def test_a_thin_boxs_faces_cover_each_pixel_as_their_exact_polygons_do(angle_deg):
    """A 5 mm box under a camera tilted 20 deg: its top and the side faces it shows (slivers of 1-3 px),
    rendered with the tests' sampling (BOX_SUPERSAMPLE), against their projected polygons' exact areas
    in each pixel. What a measurement reads is an edge averaged over a few pixels: over every 8 px of a
    face's footprint edge, the rendered area is within 0.015 px of the face's width of the exact one
    (measured: 0.008 at worst; at 4 samples, 0.067)."""
    cam = CameraSpec(width=480, height=360, focal_px=420.0, tilt_deg=20, yaw_deg=15)
    part = PartSpec(80, 50, 5.0, 60, 20, angle_deg)
    renderer = Renderer(SceneSpec(cam, (part,), n_frames=1, noise_sigma=0, blur_samples=1,
                                  supersample=BOX_SUPERSAMPLE))
    pose = part.pose(0.0)
    r0, _, c0, _ = roi = renderer._roi(part, [pose])
    cover = renderer._coverage(part, pose, roi)  # (top, sides facing X, sides facing Y)
    calib = renderer.calibration
    rot = calib.rotation()
    camera_centre = -rot.T @ calib.belt_tvec.reshape(3)
    x, y, a = pose
    c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
    hl, hw = part.length_mm / 2, part.width_mm / 2
    foot = np.array([[x + c * u - s * v, y + s * u + c * v, 0.0]
                     for u, v in ((-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw))])
    top = foot - [0.0, 0.0, part.height_mm]  # Z points into the belt
    faces = [(0, top)]
    for i in range(4):
        j = (i + 1) % 4
        outward = np.append(foot[j, :2] - foot[i, :2], 0.0)[[1, 0, 2]] * [1, -1, 0]
        if outward @ (camera_centre - foot[i]) > 0:  # the camera sees it
            faces.append((1 if i % 2 else 2, np.array([foot[i], foot[j], top[j], top[i]])))
    assert len(faces) >= 2
    for kind, corners in faces:
        polygon = cv2.projectPoints(corners, calib.belt_rvec, calib.belt_tvec, calib.camera_matrix,
                                    calib.dist_coeffs)[0].reshape(-1, 2)
        near = np.zeros(cover.shape[1:], np.uint8)
        cv2.fillConvexPoly(near, np.round((polygon - [c0, r0]) * 16).astype(np.int32), 1, shift=4)
        rows, cols = np.nonzero(cv2.dilate(near, np.ones((5, 5), np.uint8)))
        exact = np.array([_area_in_pixel(polygon, col + c0, row + r0) for row, col in zip(rows, cols, strict=True)])
        error = cover[kind, rows, cols] - exact
        start, end = polygon[0], polygon[1]  # the face's first edge (a side face's footprint edge)
        length = float(np.linalg.norm(end - start))
        along = (np.column_stack([cols + c0, rows + r0]) - start) @ ((end - start) / length)
        inner = (along > 4) & (along < length - 4)  # not the corners, where faces meet
        per_window = np.bincount((along[inner] // 8).astype(int), weights=error[inner])[1:-1] / 8
        assert len(per_window) and np.abs(per_window).max() <= 0.015, (kind, np.abs(per_window).max())


@pytest.mark.parametrize("x_mm, brighter", [(-150.0, True), (150.0, False)])
def test_a_side_lamp_lights_the_face_towards_it_and_darkens_the_one_away(x_mm, brighter):
    """The camera straight down sees a box's end face on its own side: left of the camera the one
    facing +x, right of it the one facing -x. A lamp at azimuth 0 lights the first more than its kind's
    shade and the second less; one at azimuth 90 leaves both end faces as they were."""
    cam = CameraSpec(width=320, height=240, focal_px=280.0)
    part = PartSpec(60, 40, 30.0, x_mm, 0.0, 0.0, intensity=180)

    def image(side_light: tuple[float, float]) -> np.ndarray:
        scene = SceneSpec(cam, (part,), n_frames=1, noise_sigma=0, blur_samples=1, side_light=side_light)
        return Renderer(scene).render(0)[0].astype(np.float64)

    plain = image((0.0, 0.0))
    towards_x = image((0.0, 0.25)) - plain
    towards_y = image((90.0, 0.25)) - plain
    # Only the side faces change: some pixels do, most of the part's (its top) do not.
    assert np.count_nonzero(np.abs(towards_x) > 1.0) > 20
    assert (towards_x.sum() > 0) == brighter
    # The long faces facing y are seen only edge-on from here; the end faces are lit across.
    assert np.abs(towards_y).sum() < 0.05 * np.abs(towards_x).sum()


def test_a_lamp_casts_a_boxs_shadow_away_from_it_as_long_as_its_height_over_tan_elevation():
    """A lamp at azimuth 0 (towards +x), 45 deg above the belt, casts a 20 mm box's shadow 20 mm long on
    the belt beyond its -x end, as deep as told there, its far end soft (the lamp is 6 deg across: a
    penumbra about 3 mm wide there); the belt on its +x side and past the shadow's end stays as it was,
    and a flat part casts none that shows."""
    cam = CameraSpec(width=320, height=240, focal_px=280.0)
    depth = 0.4

    def image(height_mm: float, shadow: tuple[float, float, float]) -> np.ndarray:
        part = PartSpec(60, 40, height_mm, 0.0, 0.0, 0.0, intensity=180)
        scene = SceneSpec(cam, (part,), n_frames=1, noise_sigma=0, blur_samples=1, belt_level=100.0,
                          cast_shadow=shadow, lamp_size_deg=6.0)
        return Renderer(scene).render(0)[0].astype(np.float64)

    calib = CameraSpec.calibration(cam)

    def ratio(shaded: np.ndarray, plain: np.ndarray, x_mm: float, y_mm: float = 0.0) -> float:
        u, v = cv2.projectPoints(np.array([[x_mm, y_mm, 0.0]]), calib.belt_rvec, calib.belt_tvec,
                                 calib.camera_matrix, calib.dist_coeffs)[0].reshape(2)
        at = int(round(v)), int(round(u))
        return shaded[at] / plain[at]

    lamp = (0.0, 45.0, depth)
    plain, shaded = image(20.0, (0.0, 90.0, 0.0)), image(20.0, lamp)
    for x_mm in (-33.0, -40.0, -45.0):  # 3-15 mm beyond the -x end: in the shadow
        assert abs(ratio(shaded, plain, x_mm) - (1 - depth)) < 0.02, x_mm
    assert 1 - depth + 0.05 < ratio(shaded, plain, -50.0) < 0.95  # its far end: the penumbra
    for x_mm, y_mm in ((-55.0, 0.0), (36.0, 0.0), (-40.0, 26.0)):  # past its end, the lit side, beside it
        assert abs(ratio(shaded, plain, x_mm, y_mm) - 1) <= 0.01, (x_mm, y_mm)
    flat_plain, flat_shaded = image(0.0, (0.0, 90.0, 0.0)), image(0.0, lamp)
    assert np.abs(flat_shaded - flat_plain).max() <= 1.0
