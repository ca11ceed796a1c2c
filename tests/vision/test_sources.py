"""Camera sources: simulated, VideoCapture on files and devices, replay, recorder."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from hexapod.workspace import sample_poses
from vision.cameras import front_camera, omni_camera
from vision.detect import LegPrediction, OmniDetector, PerspectiveTracker
from vision.exceptions import (
    FrameError,
    SourceClosedError,
    SourceOpenError,
    VideoWriteError,
)
from vision.render import Renderer, RenderStyle
from vision.sources import (
    ReplaySource,
    SimulatedSource,
    VideoRecorder,
    VideoSource,
    check_frame,
)


def _record(path, renderer, poses, codec="FFV1"):
    frames = []
    with VideoRecorder.for_camera(path, renderer.camera, fps=25.0, codec=codec) as rec:
        for R, t in zip(*poses, strict=True):
            img = renderer.render(R, t)
            rec.write(img)
            frames.append(img)
    return frames


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_recorded_video_gives_the_same_features(tmp_path, geometry, rng, make_camera):
    cam = make_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(blur_px=0.8, noise_std=3.0), rng=rng)
    poses = sample_poses(geometry, 6, rng)
    path = tmp_path / "legs.avi"
    frames = _record(path, r, poses)
    det = OmniDetector(cam) if cam.kind == "unified" else PerspectiveTracker(cam)
    cam.to_toml(tmp_path / "cam.toml")
    with VideoSource.from_toml(path, tmp_path / "cam.toml") as src:
        assert src.frame_count == 6
        read = list(src)
    assert len(read) == 6 and src.dropped == 0
    for k, f in enumerate(read):
        assert f.index == k and f.image.shape == (cam.height, cam.width)
        assert np.array_equal(f.image, frames[k])  # FFV1 is lossless
        pred = LegPrediction.from_pose(cam, geometry, poses[0][k], poses[1][k])
        a, b = det.detect(frames[k], pred), det.detect(f.image, pred)
        assert np.array_equal(a.edge_visible, b.edge_visible) and a.edge_visible.any()
        assert np.array_equal(a.normals[a.edge_visible], b.normals[b.edge_visible])


def test_missing_garbage_and_device_sources_raise(tmp_path, geometry):
    cam = omni_camera(geometry)
    with pytest.raises(SourceOpenError, match="no such file"):
        VideoSource(tmp_path / "nope.avi", cam)
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"this is not a video" * 100)
    with pytest.raises(SourceOpenError, match="cannot open"):
        VideoSource(junk, cam)
    with pytest.raises(SourceOpenError, match="device"):
        VideoSource(97, cam)  # no such device in the test environment


def _avi_frame_ends(data: bytes) -> list[int]:
    """Byte offsets just past each video frame chunk (``##dc``/``##db``) of the
    ``movi`` list of an AVI (RIFF) file, in file order.

    Args:
        data: The whole file.

    Returns:
        The end offset of every frame chunk (its data padded to an even length).
    """
    def chunks(start: int, end: int) -> Iterator[tuple[bytes, int, int]]:
        pos = start
        while pos + 8 <= end:
            fourcc, size = data[pos:pos + 4], int.from_bytes(data[pos + 4:pos + 8], "little")
            yield fourcc, pos, size
            pos += 8 + size + (size & 1)

    assert data[:4] == b"RIFF" and data[8:12] == b"AVI ", "not an AVI file"
    ends: list[int] = []
    for fourcc, pos, size in chunks(12, 8 + int.from_bytes(data[4:8], "little")):
        if fourcc == b"LIST" and data[pos + 8:pos + 12] == b"movi":
            ends += [p + 8 + n + (n & 1) for tag, p, n in chunks(pos + 12, pos + 8 + size)
                     if tag[2:] in (b"dc", b"db")]
    return ends


def test_truncated_video_ends_cleanly_and_counts_drops(tmp_path, geometry, rng):
    """A recording cut after its 4th frame (the index at its end lost, its header
    whole): the file opens, announces its 10 frames, gives the 4 whole ones unchanged,
    then ends, counting the 6 lost ones as dropped."""
    cam = omni_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(noise_std=3.0), rng=rng)
    path = tmp_path / "cut.avi"
    recorded = _record(path, r, sample_poses(geometry, 10, rng))
    data = path.read_bytes()
    ends = _avi_frame_ends(data)
    assert len(ends) == 10 and ends[-1] < len(data)  # 10 frames, then the index (idx1)
    path.write_bytes(data[:ends[3]])
    src = VideoSource(path, cam)
    assert src.frame_count == 10  # from the header
    frames = list(src)
    assert [f.index for f in frames] == [0, 1, 2, 3]
    for f in frames:
        assert np.array_equal(f.image, recorded[f.index])  # FFV1 is lossless
    assert src.read() is None  # ended, and stays so
    assert (src.frames_read, src.dropped) == (4, 6)


def test_wrong_size_frames_drop_or_raise(tmp_path, geometry, rng):
    omni = omni_camera(geometry)
    r = Renderer(omni, geometry, rng=rng)
    path = tmp_path / "omni.avi"
    _record(path, r, sample_poses(geometry, 3, rng))
    front = front_camera(geometry)  # 1024x780: every frame has the wrong size
    src = VideoSource(path, front)
    assert src.read() is None and src.dropped == 3
    src = VideoSource(path, front, on_bad_frame="raise")
    with pytest.raises(FrameError, match="does not match") as info:
        src.read()
    assert info.value.expected == (1024, 780) and info.value.index == 0
    src.close()
    with pytest.raises(SourceClosedError):
        src.read()


def test_check_frame():
    cam = omni_camera()
    with pytest.raises(FrameError, match="empty"):
        check_frame(np.zeros((0, 0), np.uint8), cam)
    with pytest.raises(FrameError, match="empty"):
        check_frame(None, cam)
    with pytest.raises(FrameError, match="uint8"):
        check_frame(np.zeros((480, 640), np.uint16), cam)
    bgr = np.zeros((480, 640, 3), np.uint8)
    bgr[..., 1] = 100
    g = check_frame(bgr, cam)
    assert g.shape == (480, 640) and 50 < g[0, 0] < 70


def test_replay_loops_and_simulated_source(tmp_path, geometry, rng):
    cam = omni_camera(geometry)
    r = Renderer(cam, geometry, rng=rng)
    poses = sample_poses(geometry, 4, rng)
    sim = SimulatedSource(r, zip(*poses, strict=True), dt=0.02)
    frames = list(sim)
    assert len(frames) == 4 and frames[3].timestamp_s == pytest.approx(0.06)
    live = SimulatedSource(r)
    with pytest.raises(SourceClosedError, match="set_pose"):
        live.read()
    live.set_pose(poses[0][0], poses[1][0])
    assert np.array_equal(live.read().image, frames[0].image)
    path = tmp_path / "rec.avi"
    with VideoRecorder.for_camera(path, cam) as rec:
        for f in frames:
            rec.write(f.image)
    rep = ReplaySource(path, cam, loop=True)
    out = [rep.read() for _ in range(9)]
    assert [f.index for f in out] == list(range(9))
    assert np.array_equal(out[5].image, frames[1].image)


def test_recorder_errors(tmp_path):
    with pytest.raises(VideoWriteError, match="directory"):
        VideoRecorder(tmp_path / "no" / "x.avi", 64, 48)
    with pytest.raises(VideoWriteError, match="FourCC"):
        VideoRecorder(tmp_path / "x.avi", 64, 48, codec="FFV")
    rec = VideoRecorder(tmp_path / "x.avi", 64, 48)
    with pytest.raises(VideoWriteError, match="expected"):
        rec.write(np.zeros((48, 64, 3), np.uint8))
    rec.close()
    with pytest.raises(VideoWriteError, match="closed"):
        rec.write(np.zeros((48, 64), np.uint8))
