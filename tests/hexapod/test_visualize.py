"""MeshCat viewer: records, drawings, live view, HTML export seen by a real headless browser."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from hexapod import HexapodGeometry
from hexapod.visualize import (
    LIVE_PERIOD,
    RECORD_SHAPES,
    HexapodViewer,
    RecordError,
    TrialRecord,
    load_trial,
    replay_html,
    replay_trial,
    save_trial,
    synthetic_record,
)
from hexapod.visualize.drawings import edge_planes, frustum_segments

#: Debian's Chromium as root, headless, software WebGL, no network of its own.
BROWSER_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--window-size=800,600",
                 "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--hide-scrollbars"]


def _browser() -> str:
    """``$HEXAPOD_BROWSER``, else Debian's chromium-headless-shell or chromium."""
    if os.environ.get("HEXAPOD_BROWSER"):
        return os.environ["HEXAPOD_BROWSER"]
    for name in ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise AssertionError("no headless browser: install Debian's chromium-headless-shell or "
                         "chromium ('make test' does when it may); the viewer test must run, "
                         "not skip")


def _screenshot(url: str, png: Path, tmp: Path, budget_ms: int = 3000) -> np.ndarray:
    """Screenshot of a page by headless Chromium, as RGB ints; no browser process survives."""
    import cv2

    cmd = [_browser(), *BROWSER_FLAGS, f"--user-data-dir={tmp / ('profile-' + png.stem)}",
           f"--virtual-time-budget={budget_ms}", f"--screenshot={png}", url]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        _, err = proc.communicate(timeout=90)
    finally:
        with contextlib.suppress(ProcessLookupError):  # the renderer and GPU children too
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == 0, f"chromium failed ({proc.returncode}): {err[-2000:]!r}"
    image = cv2.imread(str(png))
    assert image is not None, f"the browser wrote no screenshot {png}: {err[-2000:]!r}"
    return image[:, :, ::-1].astype(int)  # RGB


# colours of hexapod.model / hexapod.visualize as rendered (lit): hue families
def _orange(rgb: np.ndarray) -> np.ndarray:   # PLATFORM_COLOR (0.95, 0.55, 0.10)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 150) & (g > 60) & (g < 0.8 * r) & (b < 0.45 * g)


def _blue(rgb: np.ndarray) -> np.ndarray:     # LEG_BODY_COLOR (0.15, 0.35, 0.85)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (b > 120) & (b - r > 80) & (b - g > 40)


def _red(rgb: np.ndarray) -> np.ndarray:      # HIDDEN_LEG_COLOR (0.85, 0.10, 0.10)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 120) & (g < 0.35 * r) & (b < 0.35 * r)


@pytest.fixture
def record(geometry: HexapodGeometry) -> TrialRecord:
    """2 s, 101 periods; leg 3 has an edge hidden from 0.8 s to 1.2 s."""
    return synthetic_record(geometry)


# ----------------------------------------------------------------------------- records


def test_record_round_trip(record: TrialRecord, tmp_path: Path) -> None:
    path = save_trial(tmp_path / "trial.npz", **record.arrays)
    assert not list(tmp_path.glob("*.tmp.npz")), "the temporary file was not renamed"
    back = load_trial(path)
    assert back.frames == 101 and back.title == "synthetic / none / trial 0"
    assert back.path == str(path) and back.camera_kind == "perspective"
    for key in RECORD_SHAPES:
        np.testing.assert_array_equal(back[key], record[key], err_msg=key)
    assert back.geometry.leg_radius == record.geometry.leg_radius
    # the motion is what inverse kinematics says, inside the strokes
    q_min, q_max = record["stroke"]
    assert np.all((record["lengths"] > q_min) & (record["lengths"] < q_max))


def test_record_errors_name_the_file_and_the_key(record: TrialRecord, tmp_path: Path) -> None:
    with pytest.raises(RecordError, match="no such trial record"):
        load_trial(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(RecordError, match=r"junk\.npz.*not a readable"):
        load_trial(tmp_path / "junk.npz")

    arrays = {k: v for k, v in record.arrays.items() if k != "goal_rotation"}
    np.savez(tmp_path / "bad.npz", **arrays)  # type: ignore[arg-type]
    with pytest.raises(RecordError, match=r"bad\.npz: key 'goal_rotation': missing") as info:
        load_trial(tmp_path / "bad.npz")
    assert info.value.key == "goal_rotation" and info.value.path.endswith("bad.npz")

    short = dict(record.arrays, lengths=record["lengths"][:-1])
    np.savez(tmp_path / "short.npz", **short)  # type: ignore[arg-type]
    with pytest.raises(RecordError, match=r"'lengths': expected shape \(101, 6\)"):
        load_trial(tmp_path / "short.npz")
    with pytest.raises(RecordError, match="camera_kind"):
        TrialRecord(dict(record.arrays, camera_kind=np.array("orthographic")))
    with pytest.raises(RecordError, match="missing keys"):
        save_trial(tmp_path / "x.npz", t=np.zeros(3))
    assert not (tmp_path / "x.npz").exists()


# ----------------------------------------------------------------------------- drawings


def test_frustum_corners_project_to_the_image_corners(record: TrialRecord) -> None:
    T, K = record["camera_from_base"], record["camera_K"]
    w, h = record["camera_size"]
    segs = frustum_segments(T, K, record["camera_size"], "perspective").T  # (2N, 3)
    cam = segs @ T[:3, :3].T + T[:3, 3]
    apex = cam[0]
    np.testing.assert_allclose(apex, 0.0, atol=1e-12)  # the rays start at the centre
    tips = cam[1:8:2]                                   # the four corner rays
    uv = tips @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    np.testing.assert_allclose(uv, [[0, 0], [w, 0], [w, h], [0, h]], atol=1e-9)
    assert np.all(tips[:, 2] > 0), "the frustum points along +z (optical axis)"
    wide = frustum_segments(T, K, record["camera_size"], "unified").T
    rays = wide[1:24:2] @ T[:3, :3].T + T[:3, 3]
    angles = np.arccos(rays[:, 2] / np.linalg.norm(rays, axis=1))
    np.testing.assert_allclose(angles, np.deg2rad(75.0))


def test_edge_planes_are_tangent_to_the_legs(record: TrialRecord) -> None:
    g = record.geometry
    R, t = record["rotations"][0], record["translations"][0]
    T = record["camera_from_base"]
    centre = -T[:3, :3].T @ T[:3, 3]
    tris = edge_planes(g, R, t, centre)
    A = g.base_points
    B = t + g.platform_points @ R.T
    for i in range(6):
        u = (B[i] - A[i]) / np.linalg.norm(B[i] - A[i])
        normals = []
        for j in range(2):
            c, p0, p1 = tris[i, j]
            np.testing.assert_allclose(c, centre)
            n = np.cross(p0 - c, p1 - c)
            n /= np.linalg.norm(n)
            normals.append(n)
            assert abs(n @ u) < 1e-9  # the plane is parallel to the leg axis
            assert abs(abs(n @ (A[i] - c)) - g.leg_radius) < 1e-9  # at distance r: tangent
        assert abs(normals[0] @ normals[1]) < 1 - 1e-6  # two different edges


# ----------------------------------------------------------------------------- live view


def _listening_addresses(pid: int) -> list[str]:
    """Local addresses of the TCP sockets a process listens on (from /proc)."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        with np.errstate(all="ignore"):
            try:
                target = os.readlink(fd)
            except OSError:
                continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            cols = line.split()
            if cols[3] == "0A" and cols[9] in inodes:  # LISTEN
                found.append(cols[1].split(":")[0])
    return found


@pytest.mark.slow
def test_live_viewer_loopback_non_blocking_and_closed(record: TrialRecord) -> None:
    viewer = HexapodViewer(record.geometry)
    server = viewer.server_process
    assert server is not None
    try:
        assert viewer.url().startswith("http://127.0.0.1:")
        addresses = _listening_addresses(server.pid)
        assert len(addresses) >= 2, f"web and ZeroMQ sockets expected: {addresses}"
        loopback = {"0100007F", "00000000000000000000000001000000"}
        assert set(addresses) <= loopback, f"the server listens beyond loopback: {addresses}"

        viewer.show_camera(record["camera_from_base"], record["camera_K"], 640, 480,
                           kind="unified")
        viewer.show_goal(record["goal_rotation"], record["goal_translation"])
        viewer.show_edge_planes(record["rotations"][0], record["translations"][0],
                                record["edge_visible"][0])
        drawn = viewer.updates
        assert viewer.display(record["rotations"][0], record["translations"][0], force=True)
        assert viewer.updates == drawn + 1, "a forced pose is drawn before display() returns"
        drawn = viewer.updates
        began = time.perf_counter()
        for k in np.arange(100) // 2:  # a 1 kHz loop for 0.1 s, nobody watching
            assert viewer.display(record["rotations"][k], record["translations"][k],
                                  record["edge_visible"][k])
            time.sleep(0.001)
        elapsed = time.perf_counter() - began
        assert viewer.flush(timeout=ZMQ_WAIT)
        live = viewer.updates - drawn
        most = elapsed / LIVE_PERIOD + 2  # the last pose is drawn at flush
        assert 1 <= live <= most, f"{live} updates in {elapsed:.3f} s: not rate-limited"
        assert viewer._hidden[3], "the last pose (period 49) hides an edge of leg 3: red"
        _display_does_not_wait_for_a_stopped_server(viewer, record)
    finally:
        viewer.close()
    assert server.poll() is not None, "the MeshCat server is still running"
    assert not viewer._sender.is_alive()
    assert not viewer.display(record["rotations"][0], record["translations"][0])


ZMQ_WAIT = 5.0


def _display_does_not_wait_for_a_stopped_server(viewer: HexapodViewer,
                                                record: TrialRecord) -> None:
    """With the MeshCat server stopped (SIGSTOP: it reads and answers nothing), a control
    loop's display() calls all return True while the viewer's sender is stuck sending
    the first of their poses, the newest pose waits its turn, and nothing is drawn;
    once the server resumes, the stuck pose and the newest one are drawn.

    A display() that sent its pose itself would wait for the server's answer (up to the
    viewer's ZeroMQ timeout, then raise): the loop would not end in ``ZMQ_WAIT`` s with
    every call True. ``ZMQ_WAIT`` is a hang detector, not a measure of the call's cost.
    """
    server = viewer.server_process
    assert server is not None
    rotations, translations = record["rotations"], record["translations"]
    visible = record["edge_visible"]
    drawn = viewer.updates
    returned: list[bool] = []
    failures: list[BaseException] = []

    def control_loop() -> None:
        try:
            returned.append(viewer.display(rotations[0], translations[0], visible[0]))
            deadline = time.monotonic() + ZMQ_WAIT  # the sender takes the pose and sends it
            while viewer._pending is not None and time.monotonic() < deadline:
                time.sleep(0.001)
            for k in range(1, 50):  # while the sender waits for the stopped server
                returned.append(viewer.display(rotations[k], translations[k], visible[k]))
        except BaseException as exc:  # reported below, in the test's thread
            failures.append(exc)

    os.killpg(server.pid, signal.SIGSTOP)  # the server reads nothing from now on
    try:
        loop = threading.Thread(target=control_loop, name="control-loop", daemon=True)
        loop.start()
        loop.join(timeout=ZMQ_WAIT)
        assert not loop.is_alive(), "display() waits for a server that reads nothing"
        assert not failures, f"display() raised: {failures!r}"
        assert returned == [True] * 50
        assert viewer.updates == drawn, "a pose was drawn by a server that reads nothing"
        assert viewer._pending is not None, "the newest pose is not waiting for the sender"
    finally:
        os.killpg(server.pid, signal.SIGCONT)
    assert viewer.flush(timeout=ZMQ_WAIT)
    assert viewer.updates == drawn + 2, "the stuck pose and the newest one, once resumed"


# ----------------------------------------------------------------------------- export


def test_html_is_self_contained(record: TrialRecord, tmp_path: Path) -> None:
    html = replay_html(record, tmp_path / "replay.html").read_text()
    assert len(html) > 100_000  # the viewer's JavaScript is inlined
    remote = re.findall(r"<(?:script|link|img|iframe)[^>]+(?:src|href)=[\"']?(?:https?:)?//",
                        html, flags=re.IGNORECASE)
    assert not remote, f"the page loads remote resources: {remote[:3]}"
    fetched = re.findall(r"fetch\(\s*[\"']([^\"']{0,12})", html)
    assert fetched and all(u.startswith("data:") for u in fetched), set(fetched)
    assert "viewer.animator.seek" in html  # page.html#t=... opens paused at t


@pytest.mark.slow
def test_replay_in_a_real_browser(record: TrialRecord, tmp_path: Path) -> None:
    npz = save_trial(tmp_path / "trial.npz", **record.arrays)
    html, png = replay_trial(npz, tmp_path / "replay.html")
    import cv2

    curves = cv2.imread(str(png))
    assert png == tmp_path / "replay.png" and curves is not None
    assert curves.shape[1] > 1000 and curves.std() > 10  # the matplotlib companion

    shots = {t: _screenshot(f"{html.as_uri()}#t={t}", tmp_path / f"t{t}.png", tmp_path)
             for t in (0.0, 1.0, 2.0)}
    for t, image in shots.items():
        orange, blue = _orange(image).mean(), _blue(image).mean()
        assert 0.005 < orange < 0.25, f"t={t}: platform colour fraction {orange:.4f}"
        assert 0.003 < blue < 0.2, f"t={t}: leg colour fraction {blue:.4f}"
        assert 0.2 < blue / orange < 2.0, f"t={t}: legs/platform {blue / orange:.2f}"
    # leg 3 has an edge hidden at 1 s only: it is drawn red then, blue before
    assert _red(shots[1.0]).mean() > 0.001, "the hidden leg is not red at t = 1 s"
    assert _red(shots[0.0]).mean() < 0.0002, "a red leg at t = 0 (every edge visible)"
    # the platform moved between 0 s and 2 s: the images differ, and around the platform
    early, late = shots[0.0], shots[2.0]
    changed = np.any(np.abs(early - late) > 40, axis=-1)
    assert changed.mean() > 0.003, "two frames of the animation look the same"
    platform = _orange(early) | _orange(late)
    ys, xs = np.nonzero(platform)
    box = np.zeros_like(changed)
    box[ys.min():ys.max() + 1, xs.min():xs.max() + 1] = True
    assert (changed & box).sum() > 0.5 * changed.sum(), "the change is not where the platform is"


def test_records_and_newton_fk_do_not_import_pinocchio(tmp_path: Path) -> None:
    """Writing a trial record (every recorded trial of a study) and the Newton forward
    kinematics import no Pinocchio; the viewer's names import it on first use."""
    import sys

    probe = (
        "import sys\n"
        "import numpy as np\n"
        "from hexapod.fk import forward_kinematics\n"
        "from hexapod.geometry import deltalab\n"
        "from hexapod.kinematics import inverse_kinematics\n"
        "from hexapod.visualize import save_trial, synthetic_record\n"
        "from hexapod.workspace import home_pose\n"
        "g = deltalab()\n"
        "R, t = home_pose(g)\n"
        "fk = forward_kinematics(g, inverse_kinematics(g, R, t), (R, t))\n"
        "assert np.allclose(fk.translation, t)\n"
        f"save_trial({str(tmp_path / 'r.npz')!r}, **synthetic_record(g).arrays)\n"
        "before = 'pinocchio' in sys.modules\n"
        "import hexapod.visualize as v\n"
        "v.HexapodViewer\n"
        "print(before, 'pinocchio' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["False", "True"]
