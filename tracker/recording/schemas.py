"""Topics, schemas and message encoders of a recording.

Foxglove shows the file without plugins. The camera frames are ``foxglove.RawImage``
(mono8, lossless) and the parts drawn over them ``foxglove.ImageAnnotations``, both
protobuf with Foxglove's own schemas (``foxglove-schemas-protobuf``): binary, so a
frame costs a copy, not the base64 text JSON needs (a third more bytes to compress).
Our own two types stay JSON (``jsonschema``), small and readable anywhere: the poses
of every frame (the pose-stream line plus each object's raw measurement) and one flat
message per tracked object that Foxglove's Plot panel draws directly
(``/tracker/track{id==3}.x_mm``).

Recordings made before the protobuf encoding (JSON images with base64 data) still
read: ``decode_image`` takes the channel's message encoding.
"""

from __future__ import annotations

import base64
import functools
import json
import math
from dataclasses import dataclass

import cv2
import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from google.protobuf.message import DecodeError

from tracker.calibration import Calibration
from tracker.poses import FrameResult, TrackedObject

TOPIC_IMAGE = "/camera/image"
TOPIC_POSES = "/tracker/poses"
TOPIC_ANNOTATIONS = "/tracker/annotations"
TOPIC_TRACK = "/tracker/track"
FRAME_ID = "camera"

SCHEMA_RAW_IMAGE = "foxglove.RawImage"
SCHEMA_ANNOTATIONS = "foxglove.ImageAnnotations"
SCHEMA_POSES = "tracker.FramePoses"
SCHEMA_TRACK = "tracker.TrackPoint"

# Drawing style of the overlay (RGBA 0..1): measured parts green, predicted ones orange.
COLOR_MEASURED = {"r": 0.1, "g": 0.9, "b": 0.2, "a": 1.0}
COLOR_PREDICTED = {"r": 1.0, "g": 0.6, "b": 0.0, "a": 1.0}
COLOR_TEXT_BG = {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.6}
COLOR_NONE = {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0}
COLOR_ROI = {"r": 0.2, "g": 0.6, "b": 1.0, "a": 0.8}  # the region of interest
LINE_PX = 2.0
CENTROID_DIAMETER_PX = 6.0
FONT_PX = 14.0
POINTS_LINE_LOOP = int(PointsAnnotation.Type.LINE_LOOP)


# --- JSON schemas ------------------------------------------------------------------------------

def _obj(title: str | None = None, required: list[str] | None = None, **props: dict) -> dict:
    out: dict = {"type": "object", "properties": props}
    if title:
        out["title"] = title
    if required:
        out["required"] = required
    return out


_NUM, _INT, _STR, _BOOL = {"type": "number"}, {"type": "integer"}, {"type": "string"}, {"type": "boolean"}
_TIME = _obj("time", sec={"type": "integer", "minimum": 0},
             nsec={"type": "integer", "minimum": 0, "maximum": 999_999_999})
_POINT2 = _obj("foxglove.Point2", ["x", "y"], x=_NUM, y=_NUM)
_COLOR = _obj("foxglove.Color", ["r", "g", "b", "a"], r=_NUM, g=_NUM, b=_NUM, a=_NUM)
_KV = {"type": "array", "items": _obj("foxglove.KeyValuePair", ["key", "value"], key=_STR, value=_STR)}
_PAIRS = {"type": "array", "items": {"type": "array", "items": _NUM, "minItems": 2, "maxItems": 2}}


def _array(items: dict) -> dict:
    return {"type": "array", "items": items}


RAW_IMAGE_SCHEMA = _obj(
    SCHEMA_RAW_IMAGE, None,
    timestamp=_TIME, frame_id=_STR,
    width={"type": "integer", "minimum": 0}, height={"type": "integer", "minimum": 0},
    encoding=_STR, step={"type": "integer", "minimum": 0},
    data={"type": "string", "contentEncoding": "base64"},
)

ANNOTATIONS_SCHEMA = _obj(
    SCHEMA_ANNOTATIONS, ["circles", "points", "texts"],
    circles=_array(_obj("foxglove.CircleAnnotation", None, timestamp=_TIME, position=_POINT2, diameter=_NUM,
                        thickness=_NUM, fill_color=_COLOR, outline_color=_COLOR, metadata=_KV)),
    points=_array(_obj("foxglove.PointsAnnotation", None, timestamp=_TIME,
                       type={"title": "foxglove.PointsAnnotationType", "type": "integer", "minimum": 0, "maximum": 4},
                       points=_array(_POINT2), outline_color=_COLOR, outline_colors=_array(_COLOR),
                       fill_color=_COLOR, thickness=_NUM, metadata=_KV)),
    texts=_array(_obj("foxglove.TextAnnotation", None, timestamp=_TIME, position=_POINT2, text=_STR,
                      font_size=_NUM, text_color=_COLOR, background_color=_COLOR, metadata=_KV)),
)

_POSE_FIELDS = {
    "id": _INT, "x_mm": _NUM, "y_mm": _NUM, "angle_deg": _NUM, "length_mm": _NUM, "width_mm": _NUM,
    "corners_mm": _PAIRS, "vx_mm_s": _NUM, "vy_mm_s": _NUM, "measured": _BOOL,
}
_RAW = {
    "description": "the measurement of this frame before filtering (null when predicted)",
    "anyOf": [{"type": "null"}, _obj(None, None, x_mm=_NUM, y_mm=_NUM, angle_deg=_NUM, length_mm=_NUM,
                                     width_mm=_NUM, corners_mm=_PAIRS, clipped=_BOOL,
                                     bbox_px=_array(_INT), centroid_px=_array(_NUM), edge_points=_INT)],
}

POSES_SCHEMA = _obj(
    SCHEMA_POSES, ["frame", "t", "objects"],
    frame=_INT, t={"type": "number", "description": "capture time, s (pose stream)"},
    measurements={"type": "integer", "description": "blobs measured in this frame"},
    objects=_array(_obj(None, list(_POSE_FIELDS), **_POSE_FIELDS, raw=_RAW)),
)
POSES_SCHEMA["description"] = "One line of the pose stream (contract section 2) plus each object's raw measurement"

TRACK_SCHEMA = _obj(SCHEMA_TRACK, ["frame", "id"], frame=_INT, **_POSE_FIELDS)
TRACK_SCHEMA["description"] = "One tracked object in one frame, flat, for plotting"

SCHEMAS: dict[str, dict] = {
    SCHEMA_RAW_IMAGE: RAW_IMAGE_SCHEMA,
    SCHEMA_ANNOTATIONS: ANNOTATIONS_SCHEMA,
    SCHEMA_POSES: POSES_SCHEMA,
    SCHEMA_TRACK: TRACK_SCHEMA,
}
ENCODINGS = ("protobuf", "json")
# Topic -> schema name, in the order the channels are registered.
CHANNELS: dict[str, str] = {
    TOPIC_IMAGE: SCHEMA_RAW_IMAGE,
    TOPIC_POSES: SCHEMA_POSES,
    TOPIC_ANNOTATIONS: SCHEMA_ANNOTATIONS,
    TOPIC_TRACK: SCHEMA_TRACK,
}
# The Foxglove types written as protobuf (with ``encoding="protobuf"``); our own stay JSON.
PROTOBUF_TYPES = {SCHEMA_RAW_IMAGE: RawImage, SCHEMA_ANNOTATIONS: ImageAnnotations}


def schema_bytes(name: str) -> bytes:
    return json.dumps(SCHEMAS[name], separators=(",", ":")).encode()


def file_descriptor_set(message_class) -> bytes:
    """A protobuf schema as MCAP wants it: the type's file and every file it imports."""
    fds, seen = FileDescriptorSet(), set()

    def add(file) -> None:
        for dep in file.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                add(dep)
        file.CopyToProto(fds.file.add())

    add(message_class.DESCRIPTOR.file)
    return fds.SerializeToString(deterministic=True)


def channel_schema(name: str, encoding: str) -> tuple[str, bytes, str]:
    """(schema encoding, schema data, message encoding) of a channel's type."""
    if encoding == "protobuf" and name in PROTOBUF_TYPES:
        return "protobuf", file_descriptor_set(PROTOBUF_TYPES[name]), "protobuf"
    return "jsonschema", schema_bytes(name), "json"


# --- encoders ----------------------------------------------------------------------------------

def _stamp(t_ns: int) -> dict:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def _dumps(obj: dict) -> bytes:
    return json.dumps(obj, allow_nan=False, separators=(",", ":")).encode()


def image_pb_parts(image: np.ndarray, t_ns: int) -> tuple[bytes, bytes, memoryview]:
    """A foxglove.RawImage (mono8), protobuf, in three pieces whose concatenation is the message:
    every field but the pixels, the key and length of the pixels' field, the pixels themselves.
    Both encoded pieces come from the protobuf library; the pixels are not copied until they go
    into the chunk (the library's own serialisation copies a 720p frame three times: ~1 ms).
    Protobuf parsers accept fields in any order, so the pixels last is a valid message."""
    height, width = image.shape
    msg = RawImage(frame_id=FRAME_ID, width=width, height=height, encoding="mono8", step=width)
    msg.timestamp.FromNanoseconds(t_ns)
    pixels = memoryview(np.ascontiguousarray(image)).cast("B")
    return msg.SerializeToString(), _data_key(len(pixels)), pixels


@functools.lru_cache(maxsize=16)
def _data_key(size: int) -> bytes:
    """What the protobuf library writes before a RawImage ``data`` field of ``size`` bytes."""
    return RawImage(data=bytes(size)).SerializeToString()[:-size] if size else b""


def encode_image_pb(image: np.ndarray, t_ns: int) -> bytes:
    """A foxglove.RawImage (mono8), protobuf, as one bytes object."""
    return b"".join(image_pb_parts(image, t_ns))


def encode_image(image: np.ndarray, t_ns: int) -> bytes:
    """A foxglove.RawImage (mono8) as JSON (the format before protobuf; ``encoding="json"``).
    Built by hand around the base64 text: json.dumps would scan the megabyte-long string
    for characters to escape, and base64 has none."""
    height, width = image.shape
    s = _stamp(t_ns)
    head = (f'{{"timestamp":{{"sec":{s["sec"]},"nsec":{s["nsec"]}}},"frame_id":"{FRAME_ID}",'
            f'"width":{width},"height":{height},"encoding":"mono8","step":{width},"data":"')
    return b"".join((head.encode(), base64.b64encode(np.ascontiguousarray(image).data), b'"}'))


def decode_image(data: bytes, where: str, message_encoding: str = "json") -> np.ndarray:
    """The frame of a RawImage message in either encoding; ValueError if it is not a mono8 image."""
    if message_encoding == "protobuf":
        try:
            pb = RawImage.FromString(data)
        except DecodeError as exc:
            raise ValueError(f"not a protobuf RawImage ({exc})") from None
        encoding, width, height, step, payload = pb.encoding, pb.width, pb.height, pb.step, pb.data
    elif message_encoding == "json":
        msg = json.loads(data)
        encoding, width, height, step = msg.get("encoding"), msg["width"], msg["height"], msg["step"]
        payload = base64.b64decode(msg["data"])
    else:
        raise ValueError(f"message encoding {message_encoding!r} (expected protobuf or json)")
    if encoding != "mono8":
        raise ValueError(f"{where}: expected a mono8 image, got encoding {encoding!r}")
    raw = np.frombuffer(payload, dtype=np.uint8)
    if raw.size != step * height or step < width:
        raise ValueError(f"{where}: image data has {raw.size} bytes, expected {step}x{height}")
    return raw.reshape(height, step)[:, :width].copy()


def _finite(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def raw_dict(obj: TrackedObject) -> dict | None:
    m = obj.raw
    if m is None:
        return None
    r = m.rect
    return {
        "x_mm": _finite(r.x_mm), "y_mm": _finite(r.y_mm), "angle_deg": _finite(r.angle_deg),
        "length_mm": _finite(r.length_mm), "width_mm": _finite(r.width_mm),
        "corners_mm": [[_finite(x), _finite(y)] for x, y in r.corners()],
        "clipped": bool(m.clipped), "bbox_px": [int(v) for v in m.bbox_px],
        "centroid_px": [_finite(v) for v in m.centroid_px], "edge_points": int(m.edge_points),
    }


def poses_dict(result: FrameResult) -> dict:
    """The pose-stream line of this frame (exactly ``result.to_dict()``) plus raw measurements."""
    line = result.to_dict()
    for out, obj in zip(line["objects"], result.objects, strict=True):
        out["raw"] = raw_dict(obj)
    line["measurements"] = len(result.measurements)
    return line


def encode_poses(result: FrameResult) -> bytes:
    return _dumps(poses_dict(result))


def encode_track(result: FrameResult, obj: TrackedObject) -> bytes:
    return _dumps({"frame": result.frame} | obj.to_dict())


def pose_line_of(recorded: dict) -> dict:
    """The pose-stream dict logged live, from a recorded poses message (raw fields removed)."""
    objects = [{k: v for k, v in o.items() if k != "raw"} for o in recorded.get("objects", [])]
    # Every other field of the line as it was logged (e.g. the belt's motion), in its order.
    return {k: (objects if k == "objects" else v) for k, v in recorded.items() if k != "measurements"}


@dataclass(frozen=True)
class Overlay:
    """Projects belt-plane millimetres back into the distorted image, for the annotations."""

    calibration: Calibration
    part_height_mm: float = 0.0
    # The region of interest as an image polygon (pixels), drawn on every frame; None: not set.
    roi_px: np.ndarray | None = None

    def project(self, points_mm: np.ndarray) -> np.ndarray:
        c = self.calibration
        pts = np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)
        # World Z points into the belt: the top of a part h mm high is the plane Z = -h.
        world = np.column_stack([pts, np.full(len(pts), -self.part_height_mm)])
        px, _ = cv2.projectPoints(world, c.belt_rvec, c.belt_tvec, c.camera_matrix, c.dist_coeffs)
        return px.reshape(-1, 2)

    def annotations(self, result: FrameResult) -> dict:
        stamp = _stamp(result.t_ns)
        circles, points, texts = [], [], []
        if self.roi_px is not None:
            points.append({"timestamp": stamp, "type": POINTS_LINE_LOOP,
                           "points": [{"x": float(x), "y": float(y)} for x, y in self.roi_px],
                           "outline_color": COLOR_ROI, "outline_colors": [], "fill_color": COLOR_NONE,
                           "thickness": LINE_PX, "metadata": []})
        for obj in result.objects:
            color = COLOR_MEASURED if obj.measured else COLOR_PREDICTED
            px = self.project(np.vstack([obj.corners_mm, [[obj.x_mm, obj.y_mm]]]))
            if not np.all(np.isfinite(px)):
                continue
            corners, (cx, cy) = px[:4], px[4]
            points.append({"timestamp": stamp, "type": POINTS_LINE_LOOP,
                           "points": [{"x": float(x), "y": float(y)} for x, y in corners],
                           "outline_color": color, "outline_colors": [], "fill_color": COLOR_NONE,
                           "thickness": LINE_PX, "metadata": []})
            circles.append({"timestamp": stamp, "position": {"x": float(cx), "y": float(cy)},
                            "diameter": CENTROID_DIAMETER_PX, "thickness": LINE_PX, "fill_color": color,
                            "outline_color": color, "metadata": []})
            label = f"#{obj.id}" if obj.measured else f"#{obj.id} (predicted)"
            texts.append({"timestamp": stamp, "position": {"x": float(cx) + CENTROID_DIAMETER_PX, "y": float(cy)},
                          "text": label, "font_size": FONT_PX, "text_color": color,
                          "background_color": COLOR_TEXT_BG, "metadata": []})
        return {"circles": circles, "points": points, "texts": texts}

    def encode(self, result: FrameResult) -> bytes:
        """As JSON (the format before protobuf)."""
        return _dumps(self.annotations(result))

    def encode_pb(self, result: FrameResult) -> bytes:
        """The same annotations as a protobuf foxglove.ImageAnnotations."""
        return _annotations_pb(self.annotations(result)).SerializeToString()


def _color(c: dict) -> Color:
    return Color(r=c["r"], g=c["g"], b=c["b"], a=c["a"])


def _annotations_pb(d: dict) -> ImageAnnotations:
    """``Overlay.annotations`` (dicts shaped like the JSON schema) as protobuf: one drawing, two encodings."""
    msg = ImageAnnotations()
    for c in d["circles"]:
        circle = msg.circles.add(diameter=c["diameter"], thickness=c["thickness"], fill_color=_color(c["fill_color"]),
                                 outline_color=_color(c["outline_color"]), position=Point2(**c["position"]))
        circle.timestamp.seconds, circle.timestamp.nanos = c["timestamp"]["sec"], c["timestamp"]["nsec"]
    for p in d["points"]:
        points = msg.points.add(type=p["type"], thickness=p["thickness"], outline_color=_color(p["outline_color"]),
                                fill_color=_color(p["fill_color"]), points=[Point2(**q) for q in p["points"]])
        points.timestamp.seconds, points.timestamp.nanos = p["timestamp"]["sec"], p["timestamp"]["nsec"]
    for t in d["texts"]:
        text = msg.texts.add(text=t["text"], font_size=t["font_size"], text_color=_color(t["text_color"]),
                             background_color=_color(t["background_color"]), position=Point2(**t["position"]))
        text.timestamp.seconds, text.timestamp.nanos = t["timestamp"]["sec"], t["timestamp"]["nsec"]
    return msg

