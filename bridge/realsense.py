"""``--perception realsense:MODEL.pt``: a RealSense D435i and a YOLO person detector.

The reference robot's camera node (reference §1.4), on real hardware: for every colour frame,
detect people, keep the **first** person box of the detector's output (YOLO lists boxes by
confidence), read the depth at the box centre's integer pixel (the depth stream aligned to the
colour image), filter it with the asymmetric distance filter (the simulator's own function)
and publish ``[distance_m, offset_px]``; hold the last pair when nobody is detected. With
``ahead_rays`` it also publishes the reading ahead of every frame, as the simulator does
(``PerceptionConfig.ahead_rays``): the nearest valid depth at those columns of the middle row,
the far limit when none reads.

The camera and the detector are optional dependencies (``pip install '.[realsense]'``:
pyrealsense2, ultralytics). Nothing is downloaded at run time: ``MODEL.pt`` must be a file on
disk (e.g. exported once with ``yolo export`` or copied from a release). The hardware glue is
two small functions, :func:`realsense_grabber` and :func:`yolo_detector`; the pipeline
(:class:`RealSensePerception`) takes any ``grab`` and ``detect`` callables, which is how it is
tested without a camera.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from bridge.perception import Frame, PerceptionError
from follow_env.sensors.camera import CameraConfig
from follow_env.sensors.depth import ahead_column, distance_filter
from follow_env.sensors.detector import PerceptionConfig
from follow_env.sim.checks import out_of_range
from follow_env.tasks.person_follow.spec import AHEAD_SETTINGS, ahead_settings

__all__ = ["PERSON_CLASS", "RealSensePerception", "realsense_grabber", "yolo_detector"]

PERSON_CLASS = 0
"""COCO's class index of "person" (YOLO's default classes)."""

Grab = Callable[[], tuple[np.ndarray, np.ndarray]]
"""Returns ``(colour HxWx3 uint8, depth HxW in m, aligned to the colour image)``."""
Detect = Callable[[np.ndarray], Sequence[tuple[float, float, float, float, int]]]
"""Returns boxes ``(x1, y1, x2, y2, class)`` in px, in the detector's order."""

_filter = distance_filter.py_func  # the simulator's filter, run as plain Python
_column = ahead_column.py_func  # and where its reading ahead looks


class RealSensePerception:
    """The camera node on real hardware.

    :param model: the detector's weights file (``.pt``, ``.onnx``, ...), used when ``detect``
        is not given.
    :param width: colour image width, px (the offset is ``cu - width // 2``).
    :param height: colour image height, px.
    :param fps: camera frame rate.
    :param filter_history: the distance filter's history length (the simulator's default).
    :param grab: frames source instead of the RealSense pipeline (tests, other cameras).
    :param detect: detector instead of YOLO.
    :param ahead: the reading ahead's settings, ``{"ahead_rays": n, "ahead_half_angle_deg":
        a}`` (``PerceptionConfig``'s fields; an agent's ``reads_ahead``); None: not published.
    :param fx_px: the colour image's focal length, px, for the reading's columns; None: the
        camera's own (the RealSense reports it), or the simulator's camera model for ``grab``.
    :param depth_range_m: valid depths ``(min, max)``, m (the simulator's D435i range); the
        reading ahead skips the others, as the simulator does.
    """

    def __init__(
        self,
        model: str | Path | None = None,
        width: int = 640,
        height: int = 480,
        fps: int = 30,
        filter_history: int = 5,
        grab: Grab | None = None,
        detect: Detect | None = None,
        ahead: dict[str, float] | None = None,
        fx_px: float | None = None,
        depth_range_m: tuple[float, float] | None = None,
    ) -> None:
        if detect is None and (model is None or not Path(model).is_file()):
            raise PerceptionError(
                f"realsense: detector model {model!s} is not a file; give the path of a "
                "YOLO weights file (nothing is downloaded at run time)"
            )
        if not 1 <= filter_history <= 32:
            raise ValueError(f"filter_history={filter_history} is out of range: must be in [1, 32]")
        self.name = "realsense"
        self.model = None if model is None else Path(model)
        self.width, self.height, self.fps = width, height, fps
        self._grab, self._detect = grab, detect
        self._history = np.zeros(filter_history)
        self._length = filter_history
        self._stop: Callable[[], None] | None = None
        self._started = False
        # Checked by the simulator's own config (the same ranges and errors as an env's).
        unknown = sorted(set(ahead or {}) - set(AHEAD_SETTINGS))
        if unknown:
            raise ValueError(f"ahead={ahead!r}: unknown setting(s) {', '.join(unknown)}")
        settings = PerceptionConfig(**(ahead or {}))
        # Every setting, so that the runner can hold them to an agent's (bridge.runner).
        self.ahead = ahead_settings(settings)
        self._rays = settings.ahead_rays
        self._tan = float(np.tan(np.radians(settings.ahead_half_angle_deg)))
        self._exclude = settings.ahead_target == "exclude"
        camera = CameraConfig(width_px=width, height_px=height)
        self._fx = fx_px
        self._fx_model = camera.fx
        if self._rays and self._tan * (fx_px or camera.fx) >= width / 2.0:
            raise out_of_range(
                "PerceptionConfig.ahead_half_angle_deg",
                settings.ahead_half_angle_deg,
                "within the image's half-width",
            )
        self._range = depth_range_m or (camera.depth_min_m, camera.depth_max_m)
        self.reset()

    def reset(self) -> None:
        """Forget the filter's history and the held observation."""
        self._count = 0
        self._head = 0
        self._distance = 0.0
        self._offset = 0.0

    def start(self) -> None:
        if self._grab is None:
            self._grab, self._stop, fx = realsense_grabber(self.width, self.height, self.fps)
            self._fx = fx if self._fx is None else self._fx
        if self._detect is None:
            assert self.model is not None
            self._detect = yolo_detector(self.model)
        self.reset()
        self._started = True

    def read(self) -> Frame:
        if not self._started or self._grab is None or self._detect is None:
            raise PerceptionError("realsense: call start() before read()")
        # pyrealsense2 and the detector raise RuntimeError (a camera unplugged mid-run: "Frame
        # didn't arrive within 1000"): a perception error, which the runner ends a session on
        try:
            colour, depth_m = self._grab()
        except RuntimeError as exc:
            raise PerceptionError(
                f"realsense: no frame from the camera ({exc}); is it still plugged in?"
            ) from exc
        try:
            boxes = self._detect(colour)
        except RuntimeError as exc:
            which = "" if self.model is None else f" {self.model}"  # None: a given ``detect``
            raise PerceptionError(f"realsense: the detector{which} failed ({exc})") from exc
        box = next((b for b in boxes if int(b[4]) == PERSON_CLASS), None)
        if box is None:  # nothing published: the guidance law acts on the last pair
            ahead = self.reading_ahead(depth_m) if self._rays else None
            return Frame(self._distance, self._offset, False, ahead_m=ahead)
        skip = (box[0], box[2]) if self._exclude else (1.0, 0.0)
        ahead = self.reading_ahead(depth_m, skip) if self._rays else None
        x1, y1, x2, y2 = (round(v) for v in box[:4])
        cu, cv = (x1 + x2) // 2, (y1 + y2) // 2  # the integer midpoint (reference §1.4)
        cu = min(max(cu, 0), depth_m.shape[1] - 1)
        cv = min(max(cv, 0), depth_m.shape[0] - 1)
        raw = float(depth_m[cv, cu])
        if not np.isfinite(raw) or raw < 0:
            raw = 0.0  # invalid depth reads as 0, as the camera reports it
        self._distance, self._count, self._head = _filter(
            raw, self._distance, self._history, self._count, self._head, self._length
        )
        self._offset = float(cu - colour.shape[1] // 2)
        return Frame(float(self._distance), self._offset, True, ahead_m=ahead)

    def reading_ahead(self, depth_m: np.ndarray, skip: tuple[float, float] = (1.0, 0.0)) -> float:
        """The reading ahead of a depth image (m, HxW): the nearest valid depth at the
        configured columns of the middle row but those in ``skip = (u1, u2)`` (px; with
        ``ahead_target: exclude``, the detected person's box), the far limit when none is
        valid (as :func:`follow_env.sensors.depth.ahead` reads the simulated camera)."""
        lo, hi = self._range
        height, width = depth_m.shape
        fx = self._fx if self._fx is not None else self._fx_model
        best = hi
        for k in range(self._rays):
            u = min(max(_column(k, self._rays, width / 2.0, fx, self._tan), 0), width - 1)
            if skip[0] <= u <= skip[1]:
                continue
            z = float(depth_m[height // 2, u])
            if np.isfinite(z) and lo <= z <= hi and 0.0 < z < best:
                best = z
        return best

    def close(self) -> None:
        self._started = False
        if self._stop is not None:
            self._stop()
            self._stop = None


def realsense_grabber(width: int, height: int, fps: int) -> tuple[Grab, Callable[[], None], float]:
    """A RealSense colour + aligned depth stream: ``(grab, stop, fx_px)``, the last the colour
    stream's focal length."""
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise PerceptionError(
            "realsense: pyrealsense2 is not installed; pip install '.[realsense]'"
        ) from None
    pipeline = rs.pipeline()
    config = rs.config()
    config.enable_stream(rs.stream.color, width, height, rs.format.bgr8, fps)
    config.enable_stream(rs.stream.depth, width, height, rs.format.z16, fps)
    try:
        profile = pipeline.start(config)
    except RuntimeError as exc:
        raise PerceptionError(f"realsense: cannot start the camera: {exc}") from None
    scale = profile.get_device().first_depth_sensor().get_depth_scale()  # m per depth unit
    colour_profile = profile.get_stream(rs.stream.color).as_video_stream_profile()
    fx = float(colour_profile.get_intrinsics().fx)
    align = rs.align(rs.stream.color)

    def grab() -> tuple[np.ndarray, np.ndarray]:
        frames = align.process(pipeline.wait_for_frames(1000))
        colour = np.asanyarray(frames.get_color_frame().get_data())
        depth = np.asanyarray(frames.get_depth_frame().get_data()).astype(np.float64) * scale
        return colour, depth

    return grab, pipeline.stop, fx


def yolo_detector(model: Path) -> Detect:
    """An ultralytics YOLO model from a local file, as a ``detect`` callable."""
    try:
        from ultralytics import YOLO
    except ImportError:
        raise PerceptionError(
            "realsense: ultralytics is not installed; pip install '.[realsense]'"
        ) from None
    net = YOLO(str(model))

    def detect(colour: np.ndarray) -> list[tuple[float, float, float, float, int]]:
        result = net(colour, classes=[PERSON_CLASS], verbose=False)[0]
        xyxy = result.boxes.xyxy.cpu().numpy()
        cls = result.boxes.cls.cpu().numpy().astype(int)
        return [(*map(float, xyxy[k]), int(cls[k])) for k in range(len(cls))]

    return detect
