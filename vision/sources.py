"""Camera sources: simulated renderer, ``cv2.VideoCapture`` (device or file), replay,
and a video recorder.

Every source delivers :class:`Frame` objects holding a grey ``uint8`` image of the
camera's size. Failures never surface as an OpenCV error deep in the detector:

- a device or file that cannot be opened raises :class:`SourceOpenError`;
- reading a closed source, or a device that fails ``max_failures`` times in a row,
  raises :class:`SourceClosedError`;
- an unusable frame (empty, wrong size, wrong type) raises :class:`FrameError` with
  ``on_bad_frame="raise"``, or is dropped and counted (``dropped``) with
  ``on_bad_frame="drop"`` (the default);
- the end of a video file is ``read() -> None`` (iteration stops).

The recorder writes grey frames with a lossless codec (``"FFV1"`` in ``.avi``, the
default: frames read back are bit-identical; ``"MJPG"`` is lossy, about +-2 grey
levels). Both are available in ``opencv-python-headless``.
"""

from __future__ import annotations

import contextlib
import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import cv2
import numpy as np

from vision.cameras import Camera
from vision.exceptions import (
    FrameError,
    SourceClosedError,
    SourceOpenError,
    VideoWriteError,
)
from vision.render import Renderer

logger = logging.getLogger(__name__)

BAD_FRAME_POLICIES = ("drop", "raise")


@dataclass(frozen=True)
class Frame:
    """One image from a source.

    Attributes:
        image: (height, width) uint8 grey image.
        index: Index of the frame in the stream (dropped frames included).
        timestamp_s: Time of the frame [s] (stream time for files and simulations,
            ``time.monotonic()`` for devices).
    """

    image: np.ndarray
    index: int
    timestamp_s: float


class FrameSource(ABC):
    """A source of grey frames of one camera.

    Attributes:
        camera: The camera (intrinsics, size, pose) the frames come from.
        frames_read: Frames delivered.
        dropped: Frames dropped (unreadable or unusable).
    """

    camera: Camera

    def __init__(self, camera: Camera) -> None:
        self.camera = camera
        self.frames_read = 0
        self.dropped = 0
        self.closed = False

    @abstractmethod
    def read(self) -> Frame | None:
        """The next frame, or None at the end of the stream."""

    def close(self) -> None:
        """Release the source (idempotent)."""
        self.closed = True

    def __iter__(self) -> Iterator[Frame]:
        while True:
            f = self.read()
            if f is None:
                return
            yield f

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _check_open(self, name: object) -> None:
        if self.closed:
            raise SourceClosedError(name, "the source is closed")


def check_frame(image: Any, camera: Camera, source: object = "<frame>",
                index: int = -1) -> np.ndarray:
    """Validate a frame and convert it to a grey (height, width) uint8 image.

    Accepts grey images, and BGR / BGRA images (converted).

    Raises:
        FrameError: Empty, not uint8, wrong number of channels or wrong size.
    """
    size = (camera.width, camera.height)
    if image is None or not isinstance(image, np.ndarray) or image.size == 0:
        raise FrameError(source, "empty frame", index, size, None)
    if image.dtype != np.uint8:
        raise FrameError(source, f"expected uint8 pixels, got {image.dtype}", index, size,
                         image.shape)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    elif image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        image = cv2.cvtColor(image, code)
    elif image.ndim != 2:
        raise FrameError(source, f"expected a grey or BGR image, got shape {image.shape}",
                         index, size, image.shape)
    if image.shape != (camera.height, camera.width):
        raise FrameError(
            source, f"size {image.shape[1]}x{image.shape[0]} does not match the camera "
                    f"{camera.width}x{camera.height}", index, size, image.shape)
    return np.ascontiguousarray(image)


# ----------------------------------------------------------------------------- simulated
class SimulatedSource(FrameSource):
    """Frames rendered by a :class:`~vision.render.Renderer`.

    Either iterate over a sequence of poses (``poses``: ``(rotation, translation)``
    pairs; the stream ends with them), or set the pose before each :meth:`read`
    with :meth:`set_pose` (closed loop).

    Args:
        renderer: The renderer (true camera and robot).
        poses: Optional iterable of ``(rotation (3, 3), translation (3,))``.
        dt: Time between frames [s].
    """

    def __init__(self, renderer: Renderer,
                 poses: Iterable[tuple[np.ndarray, np.ndarray]] | None = None,
                 dt: float = 0.02) -> None:
        super().__init__(renderer.camera)
        self.renderer = renderer
        self.dt = float(dt)
        self._poses = iter(poses) if poses is not None else None
        self._pose: tuple[np.ndarray, np.ndarray] | None = None

    def set_pose(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        """The platform pose of the next frame (base frame, metres)."""
        self._pose = (np.asarray(rotation, float), np.asarray(translation, float))

    def read(self) -> Frame | None:
        self._check_open("simulated")
        if self._poses is not None:
            nxt = next(self._poses, None)
            if nxt is None:
                return None
            self.set_pose(*nxt)
        if self._pose is None:
            raise SourceClosedError("simulated", "no pose given: call set_pose() first")
        image = self.renderer.render(*self._pose)
        f = Frame(image, self.frames_read, self.frames_read * self.dt)
        self.frames_read += 1
        return f


# ----------------------------------------------------------------------------- video
class VideoSource(FrameSource):
    """Frames from ``cv2.VideoCapture``: a device index or a video file.

    Args:
        source: Device index (int) or path of a video file.
        camera: The camera model of the frames (e.g. ``Camera.from_toml(...)``).
        on_bad_frame: ``"drop"`` (count and skip unusable frames) or ``"raise"``
            (:class:`FrameError`).
        max_failures: Consecutive failed reads after which a device is considered
            closed (:class:`SourceClosedError`) and a file is considered ended.
        capture_factory: Builds the capture object (default ``cv2.VideoCapture``).

    Raises:
        SourceOpenError: Missing file, or a device/file OpenCV cannot open.
    """

    def __init__(
        self,
        source: int | str | Path,
        camera: Camera,
        on_bad_frame: str = "drop",
        max_failures: int = 5,
        capture_factory: Callable[..., Any] = cv2.VideoCapture,
    ) -> None:
        super().__init__(camera)
        if on_bad_frame not in BAD_FRAME_POLICIES:
            raise ValueError(f"on_bad_frame must be one of {BAD_FRAME_POLICIES}, "
                             f"got {on_bad_frame!r}")
        if max_failures < 1:
            raise ValueError(f"max_failures must be >= 1, got {max_failures}")
        self.on_bad_frame = on_bad_frame
        self.max_failures = int(max_failures)
        self.is_device = isinstance(source, int | np.integer) and not isinstance(source, bool)
        self.source: int | str = (int(source) if isinstance(source, int | np.integer)
                                  and self.is_device else str(source))
        if not self.is_device and not Path(str(source)).is_file():
            raise SourceOpenError(self.source, "no such file")
        try:
            self._cap = capture_factory(self.source)
            opened = bool(self._cap.isOpened())
        except cv2.error as exc:
            raise SourceOpenError(self.source, f"OpenCV cannot open it: {exc}") from None
        if not opened:
            what = "device" if self.is_device else "file (not a readable video?)"
            raise SourceOpenError(self.source, f"OpenCV cannot open the {what}")
        self._index = 0
        self.fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        n = self._cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.frame_count = int(n) if (not self.is_device and n and n > 0) else None

    @classmethod
    def from_toml(cls, source: int | str | Path, camera_file: str | Path,
                  **kwargs: Any) -> VideoSource:
        """A source whose camera model is read from a TOML file (:meth:`Camera.from_toml`)."""
        return cls(source, Camera.from_toml(camera_file), **kwargs)

    def _grab(self) -> tuple[bool, Any]:
        try:
            ok, img = self._cap.read()
        except cv2.error as exc:
            logger.warning("camera source %r: read failed: %s", self.source, exc)
            return False, None
        return bool(ok), img

    def _at_end(self) -> bool:
        return self.frame_count is not None and self._index >= self.frame_count

    def read(self) -> Frame | None:
        self._check_open(self.source)
        failures = 0
        while True:
            if not self.is_device and self._at_end():
                return None
            ok, img = self._grab()
            index = self._index
            if not ok or img is None:
                failures += 1
                if self.is_device:
                    self.dropped += 1
                    if failures >= self.max_failures:
                        raise SourceClosedError(
                            self.source, f"{failures} consecutive failed reads (device "
                                         f"disconnected?)")
                    continue
                # A file: the end, or a corrupt frame before the announced end.
                if self.frame_count is None or failures >= self.max_failures:
                    if self.frame_count is not None and index < self.frame_count:
                        self.dropped += self.frame_count - index
                        logger.warning("camera source %r: stream ended at frame %d of %d",
                                       self.source, index, self.frame_count)
                        self._index = self.frame_count
                    return None
                self._index += 1
                self.dropped += 1
                continue
            self._index += 1
            try:
                image = check_frame(img, self.camera, self.source, index)
            except FrameError:
                if self.on_bad_frame == "raise":
                    raise
                self.dropped += 1
                logger.debug("camera source %r: dropped frame %d", self.source, index)
                continue
            if self.is_device:
                stamp = time.monotonic()
            else:
                stamp = index / self.fps if self.fps > 0 else float(index)
            self.frames_read += 1
            return Frame(image, index, stamp)

    def close(self) -> None:
        if not self.closed:
            with contextlib.suppress(cv2.error):
                self._cap.release()
        super().close()


class ReplaySource(VideoSource):
    """Replay of a recorded video file, optionally looped and paced at its frame rate.

    Args:
        path: The video file.
        camera: The camera model of the recording.
        loop: Restart at the end instead of ending the stream.
        realtime: Sleep so that frames are delivered at the file's frame rate.
        **kwargs: As :class:`VideoSource`.
    """

    def __init__(self, path: str | Path, camera: Camera, loop: bool = False,
                 realtime: bool = False, **kwargs: Any) -> None:
        if isinstance(path, int):
            raise SourceOpenError(path, "a replay needs a file, not a device index")
        super().__init__(path, camera, **kwargs)
        self.loop = bool(loop)
        self.realtime = bool(realtime)
        self._t0: float | None = None
        self._offset = 0

    def read(self) -> Frame | None:
        f = super().read()
        if f is None and self.loop and self.frames_read > 0:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            self._offset += self._index
            self._index = 0
            f = super().read()
        if f is None:
            return None
        f = Frame(f.image, f.index + self._offset, f.timestamp_s)
        if self.realtime and self.fps > 0:
            now = time.monotonic()
            if self._t0 is None:
                self._t0 = now
            due = self._t0 + (self.frames_read - 1) / self.fps
            if due > now:
                time.sleep(due - now)
        return f


# ----------------------------------------------------------------------------- writer
class VideoRecorder:
    """Records grey frames to a video file.

    Args:
        path: Output file (``.avi`` for FFV1 / MJPG).
        width: Frame width [px].
        height: Frame height [px].
        fps: Frame rate written in the file [1/s].
        codec: FourCC: ``"FFV1"`` (lossless, default) or ``"MJPG"`` (lossy).

    Raises:
        VideoWriteError: The codec or the path cannot be used.
    """

    def __init__(self, path: str | Path, width: int, height: int, fps: float = 50.0,
                 codec: str = "FFV1") -> None:
        if len(codec) != 4:
            raise VideoWriteError(str(path), f"codec must be a 4-character FourCC, got "
                                             f"{codec!r}")
        self.path = Path(path)
        self.width, self.height = int(width), int(height)
        if not self.path.parent.is_dir():
            raise VideoWriteError(str(path), "the directory does not exist")
        fourcc = cv2.VideoWriter.fourcc(*codec)
        self._writer: cv2.VideoWriter | None = cv2.VideoWriter(
            str(self.path), fourcc, float(fps), (self.width, self.height), isColor=False)
        if not self._writer.isOpened():
            raise VideoWriteError(str(path), f"OpenCV cannot write codec {codec!r} here")
        self.frames_written = 0

    @classmethod
    def for_camera(cls, path: str | Path, camera: Camera, fps: float = 50.0,
                   codec: str = "FFV1") -> VideoRecorder:
        """A recorder of the camera's image size."""
        return cls(path, camera.width, camera.height, fps, codec)

    def write(self, image: np.ndarray) -> None:
        """Append a (height, width) uint8 grey frame."""
        if self._writer is None:
            raise VideoWriteError(str(self.path), "the recorder is closed")
        if (not isinstance(image, np.ndarray) or image.dtype != np.uint8
                or image.shape != (self.height, self.width)):
            got = getattr(image, "shape", None)
            raise VideoWriteError(str(self.path), f"expected a ({self.height}, {self.width}) "
                                                  f"uint8 frame, got {got}")
        self._writer.write(image)
        self.frames_written += 1

    def close(self) -> None:
        """Finish the file (idempotent)."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None

    def __enter__(self) -> VideoRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
