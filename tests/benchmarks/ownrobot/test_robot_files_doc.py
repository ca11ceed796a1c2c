"""docs/robot-files.md: a new robot written from the page's examples alone passes
``check`` and runs a short study; the page's snippets and figures are what the code does."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import log_so3
from vision.cameras import camera_preset, load_camera

PAGE = Path(__file__).resolve().parents[3] / "docs" / "robot-files.md"


def _examples() -> dict[str, str]:
    text = PAGE.read_text()
    return dict(re.findall(r"<!-- example: (\S+) -->\n```toml\n(.*?)```", text, re.S))


def _blocks(lang: str) -> list[str]:
    """The fenced blocks of the page in language ``lang`` ("" for plain ones), dedented."""
    import textwrap

    out, current, current_lang = [], None, ""
    for line in PAGE.read_text().splitlines():
        fence = line.strip()
        if fence.startswith("```"):
            if current is None:
                current, current_lang = [], fence[3:]
            else:
                if current_lang == lang:
                    out.append(textwrap.dedent("\n".join(current)) + "\n")
                current = None
        elif current is not None:
            current.append(line)
    return out


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    examples = _examples()
    assert set(examples) == {"my-hexapod.toml", "my-camera.toml", "my-study.toml"}
    for name, text in examples.items():
        (tmp_path / name).write_text(text)
    return tmp_path


def test_the_example_robot_is_the_one_described(folder: Path) -> None:
    g = HexapodGeometry.from_toml(folder / "my-hexapod.toml")
    assert np.linalg.norm(g.base_points[:, :2], axis=1) == pytest.approx(0.350, abs=1e-6)
    assert np.linalg.norm(g.platform_points[:, :2], axis=1) == pytest.approx(0.200, abs=1e-6)
    assert g.stroke == (0.380, 0.540) and g.leg_radius == 0.015
    # the camera file is the front preset's placement for this robot (as the page says)
    cam = load_camera(folder / "my-camera.toml")
    preset = camera_preset("front", g)
    assert cam.camera_from_base.translation == pytest.approx(
        preset.camera_from_base.translation, abs=1e-6)
    assert np.degrees(log_so3(cam.camera_from_base.rotation.T
                              @ preset.camera_from_base.rotation)) == pytest.approx(
        np.zeros(3), abs=2e-3)
    assert pytest.approx(preset.K, abs=0.01) == cam.K


def test_the_python_snippets_write_the_examples(folder: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    robot_snippet, pose_snippet = _blocks("python")
    work = folder / "snippet"
    work.mkdir()
    monkeypatch.chdir(work)
    exec(compile(robot_snippet, "robot-files.md", "exec"), {})
    made = HexapodGeometry.from_toml(work / "my-hexapod.toml")
    example = HexapodGeometry.from_toml(folder / "my-hexapod.toml")
    assert made.base_points == pytest.approx(example.base_points, abs=1e-6)
    assert made.platform_points == pytest.approx(example.platform_points, abs=1e-6)
    assert made.stroke == example.stroke
    # the look-at snippet, from the placement the page states (1037 mm, azimuth 30 deg,
    # aim point 277 mm high), gives the example's pose
    preset = camera_preset("front", example).camera_from_base
    eye = -preset.rotation.T @ preset.translation
    assert np.hypot(*eye[:2]) == pytest.approx(1.037, abs=5e-4)
    assert np.degrees(np.arctan2(eye[1], eye[0])) == pytest.approx(30.0)
    target = np.array([0.0, 0.0, 0.265 * example.home_height / 0.3594098])
    assert target[2] == pytest.approx(0.277, abs=5e-4)
    printed: list[str] = []  # the snippet as shown, its own eye and target (it once
    exec(compile(pose_snippet, "robot-files.md", "exec"),  # had them in a comment only)
         {"print": lambda *a: printed.append(" ".join(str(x) for x in a))})
    table = _examples()["my-camera.toml"]
    assert len(printed) == 2
    for line in printed:
        key, values = line.split(" = ")
        want = re.search(rf"{key} = (\[.*?\])", table)
        assert want is not None  # within 0.01 mm and 0.01 deg
        assert json.loads(values) == pytest.approx(json.loads(want.group(1)), abs=1e-2)


@pytest.mark.slow
def test_a_robot_from_the_page_passes_check_and_runs(folder: Path,
                                                     capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch
                                                     ) -> None:
    study = folder / "my-study.toml"
    monkeypatch.chdir(folder)  # the page's command, as typed in the folder of the files
    (folder / "docs").mkdir(exist_ok=True)
    assert main(["check", "my-study.toml", "--picture", "docs/check-my-hexapod.png"]) == 0
    out = capsys.readouterr().out
    assert "The setup can run." in out
    # the output shown on the page is the command's
    shown = next(b for b in _blocks("") if "The setup can run." in b)
    for line in shown.splitlines():
        if line.strip() != "...":
            assert line in out, line
    run = folder / "run"
    assert main(["run", str(study), "--out", str(run), "--trials", "2", "--no-progress"]) == 0
    capsys.readouterr()
    rows = [json.loads(x) for x in (run / "results.jsonl").read_text().splitlines()]
    assert len(rows) == 4
    assert all(r["converged"] and not r.get("failure") for r in rows), rows
