"""Renderer of conveyor scenes whose geometry is known exactly.

Every pixel is a ray through the exact OpenCV distortion model (inverted once,
to 1e-12 px, for every pixel centre). A ray is intersected with each box
analytically, so the only approximations are the anti-aliasing (S x S samples in
pixels that an edge crosses, rays interpolated between the exact pixel-centre
rays) and the motion blur (samples spread over the exposure).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracker.calibration import Calibration, homography_from_pose
from tracker.castshadow import lamp_reaches, polygon_cover, shadow_polygon
from tracker.geometry import rectangle_corners, wrap_angle_deg
from tracker.raycast import edge_pixels, interpolate, pixel_rays, subpixel_pattern

# k1, k2, p1, p2, k3 of a wide-angle machine-vision lens (strong barrel distortion).
STRONG_DISTORTION = (-0.32, 0.12, 0.0008, -0.0006, -0.02)
# Face shading relative to the top face: sides facing X and Y.
_SIDE_SHADE = (0.8, 0.65)
# Step (px) of the coarse grid that locates each box before the per-pixel pass.
_COARSE_STEP = 4


@dataclass(frozen=True)
class CameraSpec:
    """A camera looking down at the belt; world frame as in the contract (Z into the belt)."""

    width: int = 640
    height: int = 480
    focal_px: float = 560.0
    principal_offset_px: tuple[float, float] = (3.5, -2.5)
    dist_coeffs: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    height_mm: float = 700.0
    tilt_deg: float = 0.0
    yaw_deg: float = 0.0
    # Where the optical axis meets the belt.
    target_mm: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not 500 <= self.height_mm <= 1200 or not 0 <= self.tilt_deg <= 25:
            raise ValueError(
                f"camera: expected height 500-1200 mm and tilt 0-25 deg, "
                f"got {self.height_mm} mm, {self.tilt_deg} deg"
            )

    def calibration(self) -> Calibration:
        k = np.array(
            [
                [self.focal_px, 0.0, self.width / 2 - 0.5 + self.principal_offset_px[0]],
                [0.0, self.focal_px, self.height / 2 - 0.5 + self.principal_offset_px[1]],
                [0.0, 0.0, 1.0],
            ]
        )
        yaw, tilt = math.radians(self.yaw_deg), math.radians(self.tilt_deg)
        rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
        rx = np.array([[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)], [0, math.sin(tilt), math.cos(tilt)]])
        cam_to_world = rz @ rx
        axis = cam_to_world[:, 2]
        centre = np.array([*self.target_mm, 0.0]) - (self.height_mm / axis[2]) * axis
        rot = cam_to_world.T
        tvec = (-rot @ centre).reshape(3, 1)
        rvec, _ = cv2.Rodrigues(rot)
        return Calibration(
            self.width, self.height, k, np.array([self.dist_coeffs], dtype=np.float64), None,
            rvec, tvec, homography_from_pose(k, rvec, tvec), source="<synthetic camera>",
        )


@dataclass(frozen=True)
class PartSpec:
    """A box moving at constant velocity (and optional constant rotation)."""

    length_mm: float
    width_mm: float
    height_mm: float = 0.0
    x0_mm: float = 0.0
    y0_mm: float = 0.0
    angle0_deg: float = 0.0
    vx_mm_s: float = 0.0
    vy_mm_s: float = 0.0
    omega_deg_s: float = 0.0
    intensity: float = 200.0
    # Height of its bottom face above the belt: a part lying on another one, or a bracket over the belt.
    z_mm: float = 0.0
    # "box"; "cylinder": lying down along its length, width_mm across (height_mm is ignored);
    # "bag": a soft pouch, an ellipsoid of these length, width and height lying on the belt. Parts
    # that are no prism, for the limits of the box model.
    shape: str = "box"

    def pose(self, t_s: float) -> tuple[float, float, float]:
        return (
            self.x0_mm + self.vx_mm_s * t_s,
            self.y0_mm + self.vy_mm_s * t_s,
            self.angle0_deg + self.omega_deg_s * t_s,
        )


@dataclass(frozen=True)
class SceneSpec:
    camera: CameraSpec = field(default_factory=CameraSpec)
    parts: tuple[PartSpec, ...] = ()
    fps: float = 60.0
    n_frames: int = 60
    exposure_s: float = 0.002
    blur_samples: int = 5
    supersample: int = 8
    noise_sigma: float = 1.5
    # Relative lighting flicker: each frame's gain is uniform in [1 - f, 1 + f].
    flicker: float = 0.0
    belt_level: float = 60.0
    seed: int = 0
    # A knurled belt: a diamond texture of this amplitude (grey levels, 0: a plain belt) and
    # period (mm on the belt), drawn on the belt plane and moving with the belt's velocity.
    belt_texture: float = 0.0
    belt_texture_period_mm: float = 6.0
    belt_velocity_mm_s: tuple[float, float] = (0.0, 0.0)
    # Fixed things above the belt (a bracket, a sensor): drawn over the parts, never in the truth.
    occluders: tuple[PartSpec, ...] = ()
    # A lamp to one side (azimuth deg on the belt, strength): each side face of a box is lit by
    # 1 + strength * cos(its outward normal's azimuth - the lamp's) times its kind's shade, so that a
    # face and the one opposite differ (0: every face of a kind alike, as under a lamp overhead).
    side_light: tuple[float, float] = (0.0, 0.0)
    # A lamp that casts each part's shadow on the belt (tracker/castshadow.py): (azimuth deg, elevation
    # deg above the belt, depth: the fraction of the belt's light the shadow takes; 0: none), the lamp
    # lamp_size_deg across as seen from the belt (its shadows' penumbra). Parts are drawn over every
    # shadow, theirs and the others'.
    cast_shadow: tuple[float, float, float] = (0.0, 90.0, 0.0)
    lamp_size_deg: float = 4.0

    def __post_init__(self) -> None:
        _, elevation_deg, depth = self.cast_shadow
        if not 0 < elevation_deg <= 90 or not 0 <= depth <= 1:
            raise ValueError(f"cast_shadow: expected an elevation in (0, 90] deg and a depth in [0, 1], "
                             f"got {self.cast_shadow}")

    def t_ns(self, index: int) -> int:
        """Capture time of frame ``index``: the middle of its exposure."""
        return round(index * 1e9 / self.fps)


class Renderer:
    """Renders frames of a SceneSpec; frames are independent (random access, deterministic)."""

    def __init__(self, scene: SceneSpec) -> None:
        self.scene = scene
        cam = scene.camera
        self.calibration = cam.calibration()
        calib = self.calibration
        rot = calib.rotation()
        self._centre = -rot.T @ calib.belt_tvec.reshape(3)
        norm = pixel_rays(calib.camera_matrix, calib.dist_coeffs, cam.width, cam.height)
        # World direction of the ray through each pixel centre (not normalised; linear in x, y).
        self._rays = norm[..., 0:1] * rot[0] + norm[..., 1:2] * rot[1] + rot[2]
        self._background = self._belt_image()
        # Where each pixel's ray meets the belt plane (Z = 0), for a texture that moves with it.
        with np.errstate(divide="ignore", invalid="ignore"):
            reach = -self._centre[2] / self._rays[..., 2]
        self._belt_xy = (self._centre[:2] + reach[..., None] * self._rays[..., :2]).astype(np.float64)

    def _belt_image(self) -> np.ndarray:
        cam = self.scene.camera
        v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float32)
        r2 = ((u - cam.width / 2) ** 2 + (v - cam.height / 2) ** 2) / (cam.width**2 / 4)
        # Static illumination falloff and a soft pattern: the reference must be learnt, not assumed flat.
        shade = (1.0 - 0.12 * r2) * (1.0 + 0.04 * np.cos(u / 37.0) * np.cos(v / 23.0))
        return (self.scene.belt_level * shade).astype(np.float32)

    def _texture(self, times: np.ndarray) -> np.ndarray:
        """The belt's diamond texture at the exposure's sample times (blurred by the motion like parts)."""
        sc = self.scene
        k = 2 * math.pi / sc.belt_texture_period_mm
        vx, vy = sc.belt_velocity_mm_s
        out = np.zeros(self._belt_xy.shape[:2], dtype=np.float64)
        for t in times:
            x = self._belt_xy[..., 0] - vx * t
            y = self._belt_xy[..., 1] - vy * t
            out += np.sin(k * (x + y)) * np.sin(k * (x - y))
        return (sc.belt_texture * out / len(times)).astype(np.float32)

    # --- geometry ---------------------------------------------------------------------------
    def _hits(self, rays: np.ndarray, part: PartSpec, pose: tuple[float, float, float]) -> np.ndarray:
        """Face hit by each ray: 0 none, 1 top, 2 side facing X, 3 side facing Y."""
        x, y, angle = pose
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        o = self._centre - np.array([x, y, 0.0])
        ox, oy, oz = c * o[0] + s * o[1], -s * o[0] + c * o[1], o[2]
        dx = c * rays[..., 0] + s * rays[..., 1]
        dy = -s * rays[..., 0] + c * rays[..., 1]
        dz = rays[..., 2]
        if part.shape == "cylinder":
            return self._cylinder_hits(part, (ox, oy, oz), (dx, dy, dz))
        if part.shape == "bag":
            return self._bag_hits(part, (ox, oy, oz), (dx, dy, dz))
        with np.errstate(divide="ignore", invalid="ignore"):
            near, far = [], []
            for o_i, d_i, lo, hi in (
                (ox, dx, -part.length_mm / 2, part.length_mm / 2),
                (oy, dy, -part.width_mm / 2, part.width_mm / 2),
                (oz, dz, -part.z_mm - part.height_mm, -part.z_mm),
            ):
                t1, t2 = (lo - o_i) / d_i, (hi - o_i) / d_i
                parallel = d_i == 0
                inside = (o_i >= lo) & (o_i <= hi)
                near.append(np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2)))
                far.append(np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2)))
        near_all = np.stack(near)
        t_near = near_all.max(axis=0)
        t_far = np.minimum(np.minimum(far[0], far[1]), far[2])
        hit = (t_near <= t_far) & (t_far > 0)
        # Axis whose slab is entered last is the face hit: z -> top (1), x -> 2, y -> 3.
        face = np.array([2, 3, 1], dtype=np.uint8)[near_all.argmax(axis=0)]
        return np.where(hit, face, 0).astype(np.uint8)

    @staticmethod
    def _cylinder_hits(part: PartSpec, o: tuple, d: tuple) -> np.ndarray:
        """A cylinder lying along the part's x: 1 where the ray meets its upper surface (facing up), 2 its
        lower flanks, 3 its end caps (in the part's frame: o the camera centre, d the ray directions)."""
        ox, oy, oz = o
        dx, dy, dz = d
        r = part.width_mm / 2
        zc = -part.z_mm - r  # the axis (world Z points into the belt)
        with np.errstate(divide="ignore", invalid="ignore"):
            a = dy * dy + dz * dz
            b = 2 * (oy * dy + (oz - zc) * dz)
            disc = b * b - 4 * a * (oy * oy + (oz - zc) ** 2 - r * r)
            root = np.sqrt(np.maximum(disc, 0.0))
            t1, t2 = (-b - root) / (2 * a), (-b + root) / (2 * a)
            tx1, tx2 = (-part.length_mm / 2 - ox) / dx, (part.length_mm / 2 - ox) / dx
        tx_near, tx_far = np.minimum(tx1, tx2), np.maximum(tx1, tx2)
        t_in, t_out = np.maximum(t1, tx_near), np.minimum(t2, tx_far)
        hit = (disc > 0) & (t_in <= t_out) & (t_out > 0)
        facing_up = (oz + t1 * dz - zc) / r < -0.7
        face = np.where(t1 >= tx_near, np.where(facing_up, 1, 2), 3)
        return np.where(hit, face, 0).astype(np.uint8)

    @staticmethod
    def _bag_hits(part: PartSpec, o: tuple, d: tuple) -> np.ndarray:
        """An ellipsoid lying on the belt: 1 where the ray meets its upper half, 2 its flanks facing the
        part's x, 3 those facing its y (a soft object's shading, in bands like a box's faces)."""
        semi = (part.length_mm / 2, part.width_mm / 2, part.height_mm / 2)
        zc = -part.z_mm - semi[2]  # its centre (world Z points into the belt)
        # In units of its semi-axes the ellipsoid is the unit sphere.
        ox, oy, oz = o[0] / semi[0], o[1] / semi[1], (o[2] - zc) / semi[2]
        dx, dy, dz = d[0] / semi[0], d[1] / semi[1], d[2] / semi[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            a = dx * dx + dy * dy + dz * dz
            b = 2 * (ox * dx + oy * dy + oz * dz)
            disc = b * b - 4 * a * (ox * ox + oy * oy + oz * oz - 1.0)
            t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a)
        hit = (disc > 0) & (t > 0)
        px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
        face = np.where(pz < -0.7, 1, np.where(np.abs(px) > np.abs(py), 2, 3))
        return np.where(hit, face, 0).astype(np.uint8)

    def _roi(self, part: PartSpec, poses: list[tuple[float, float, float]]) -> tuple[int, int, int, int] | None:
        step = _COARSE_STEP
        coarse = self._rays[::step, ::step]
        hit = np.zeros(coarse.shape[:2], dtype=bool)
        for pose in poses:
            hit |= self._hits(coarse, part, pose) > 0
        if not hit.any():
            return None
        rows, cols = np.nonzero(hit.any(axis=1))[0], np.nonzero(hit.any(axis=0))[0]
        h, w = self._rays.shape[:2]
        pad = step + 2
        return (
            max(0, rows[0] * step - pad), min(h, rows[-1] * step + pad + 1),
            max(0, cols[0] * step - pad), min(w, cols[-1] * step + pad + 1),
        )

    def _coverage(self, part: PartSpec, pose, roi) -> np.ndarray:
        """Fraction of each ROI pixel covered by each face: array (3, rows, cols)."""
        r0, r1, c0, c1 = roi
        labels = self._hits(self._rays[r0:r1, c0:c1], part, pose)
        cover = np.zeros((3, *labels.shape), dtype=np.float32)
        for face in (1, 2, 3):
            cover[face - 1][labels == face] = 1.0
        er, ec = edge_pixels(labels)
        if er.size:
            ou, ov = subpixel_pattern(self.scene.supersample)
            su = (ec + c0)[:, None] + ou
            sv = (er + r0)[:, None] + ov
            sub = self._hits(interpolate(self._rays, su, sv), part, pose)
            for face in (1, 2, 3):
                cover[face - 1, er, ec] = (sub == face).mean(axis=1)
        return cover

    def _paint(self, part: PartSpec, poses: list, roi) -> tuple[np.ndarray, np.ndarray]:
        """A part's light over the ROI (its faces' coverage times their levels) and its coverage, each
        the mean over the exposure's sample ``poses``."""
        paint, total = 0.0, 0.0
        for pose in poses:
            cover = self._coverage(part, pose, roi)
            shades = (1.0, *(kind * self._lamp(part, pose, axis) for axis, kind in enumerate(_SIDE_SHADE)))
            paint = paint + sum(cover[i] * (part.intensity * shades[i]) for i in range(3))
            total = total + cover.sum(axis=0)
        return paint / len(poses), total / len(poses)

    def _lamp(self, part: PartSpec, pose: tuple[float, float, float], axis: int) -> float:
        """How the side lamp lights the face of ``part`` (at ``pose``) facing its x (``axis`` 0) or y (1)
        that the camera sees (on the camera's side of the part)."""
        azimuth_deg, strength = self.scene.side_light
        if not strength or part.shape != "box":
            return 1.0
        x, y, angle = pose
        normal = math.radians(angle + 90.0 * axis)
        towards = (self._centre[0] - x) * math.cos(normal) + (self._centre[1] - y) * math.sin(normal)
        if towards < 0:
            normal += math.pi
        return 1.0 + strength * math.cos(normal - math.radians(azimuth_deg))

    def _shadow(self, times: np.ndarray) -> np.ndarray:
        """How deep in a shadow each pixel's belt lies (0-1; the deepest of the parts' and occluders',
        each the mean over the exposure's ``times`` and the lamp's disk). A cylinder's or a bag's is its
        bounding box's."""
        sc = self.scene
        reaches = lamp_reaches(sc.cast_shadow[0], sc.cast_shadow[1], sc.lamp_size_deg)
        out = np.zeros(self._belt_xy.shape[:2], dtype=np.float32)
        for part in (*sc.parts, *sc.occluders):
            top_mm = part.z_mm + (part.width_mm if part.shape == "cylinder" else part.height_mm)
            polygons = [shadow_polygon(part.length_mm, part.width_mm, part.z_mm, top_mm, part.pose(float(t)), reach)
                        for t in times for reach in reaches]
            # Only the pixels whose belt lies within the shadows' bounds: the whole frame costs 4x a render.
            outlines = np.vstack(polygons)
            near = np.all((self._belt_xy >= outlines.min(axis=0)) & (self._belt_xy <= outlines.max(axis=0)), axis=-1)
            if not near.any():
                continue
            rows, cols = np.nonzero(near.any(axis=1))[0], np.nonzero(near.any(axis=0))[0]
            window = np.s_[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
            cover = sum(polygon_cover(self._belt_xy[window], p) for p in polygons)
            out[window] = np.maximum(out[window], cover / len(polygons))
        return out

    # --- frames -----------------------------------------------------------------------------
    def _sample_times(self, index: int) -> np.ndarray:
        sc = self.scene
        t = index / sc.fps
        n = sc.blur_samples
        return t + ((np.arange(n) + 0.5) / n - 0.5) * sc.exposure_s

    def render(self, index: int) -> tuple[np.ndarray, dict]:
        """Frame ``index`` as 8-bit grey, and its ground truth in the pose-stream shape."""
        sc = self.scene
        rng = np.random.default_rng([sc.seed, index])
        image = self._background.copy()
        times = self._sample_times(index)
        if sc.belt_texture:
            image += self._texture(times)
        if sc.cast_shadow[2]:
            image *= 1.0 - sc.cast_shadow[2] * self._shadow(times)
        truth: list[dict | None] = [None] * len(sc.parts)
        h, w = image.shape
        # Painted from the belt up: a part lying on another one hides it; occluders hide everything.
        order = sorted(range(len(sc.parts)), key=lambda i: sc.parts[i].z_mm)
        for part_id in [*order, *range(-len(sc.occluders), 0)]:
            part = sc.parts[part_id] if part_id >= 0 else sc.occluders[part_id]
            poses = [part.pose(float(t)) for t in times]
            roi = self._roi(part, poses)
            visible_px = 0
            border_px = -1
            if roi is not None:
                r0, r1, c0, c1 = roi
                paint, total = self._paint(part, poses, roi)
                image[r0:r1, c0:c1] = image[r0:r1, c0:c1] * (1 - total) + paint
                rows, cols = np.nonzero(total > 0)
                visible_px = int(rows.size)
                if visible_px:
                    border_px = int(min(rows.min() + r0, cols.min() + c0,
                                        h - 1 - (rows.max() + r0), w - 1 - (cols.max() + c0)))
            if part_id >= 0:
                truth[part_id] = self._truth(part_id, part, index, visible_px, border_px)
        if sc.flicker:
            image *= 1.0 + rng.uniform(-sc.flicker, sc.flicker)
        if sc.noise_sigma:
            image += rng.normal(0.0, sc.noise_sigma, image.shape).astype(np.float32)
        frame = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        return frame, {"frame": index, "t": sc.t_ns(index) / 1e9, "objects": truth}

    def _truth(self, part_id: int, part: PartSpec, index: int, visible_px: int, border_px: int) -> dict:
        x, y, angle = part.pose(index / self.scene.fps)
        length, width = part.length_mm, part.width_mm
        if width > length:
            length, width, angle = width, length, angle + 90.0
        corners = rectangle_corners(x, y, angle, length, width)
        omega = math.radians(part.omega_deg_s)
        return {
            "id": part_id, "x_mm": x, "y_mm": y, "angle_deg": wrap_angle_deg(angle),
            "length_mm": length, "width_mm": width, "corners_mm": corners.tolist(),
            "vx_mm_s": part.vx_mm_s, "vy_mm_s": part.vy_mm_s, "measured": True,
            "omega_rad_s": omega, "height_mm": part.height_mm,
            # Pixels it covers and its distance from the image border (-1: not in view).
            "visible_px": visible_px, "border_px": border_px,
        }


def mpeg4_round_trip(frames: list[np.ndarray], fps: float) -> list[np.ndarray]:
    """Grey frames through a real lossy codec (MPEG-4 part 2, as the real mixed-items video) and back:
    the blocks and ringing a compressed camera stream adds to what the renderer draws."""
    h, w = frames[0].shape
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "belt.avi")
        writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        if not writer.isOpened():
            raise RuntimeError("this OpenCV cannot encode MPEG-4")
        for f in frames:
            writer.write(cv2.cvtColor(f, cv2.COLOR_GRAY2BGR))
        writer.release()
        cap = cv2.VideoCapture(path)
        back = []
        while True:
            ok, image = cap.read()
            if not ok:
                break
            back.append(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    if len(back) != len(frames):
        raise RuntimeError(f"MPEG-4 round trip: {len(frames)} frames in, {len(back)} out")
    return back
