"""``viz``'s options on a real run: --still needs --html and a period of the trial, the
page's folder is made, and the animation shows the nearest period and the last."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from hexapod.visualize.viewer import nearest_periods


def test_each_frame_shows_the_nearest_period_and_the_last_one_is_shown() -> None:
    """At 50 Hz and 25 fps frame k showed period 2k - 1 (one late) and never the last
    period, the pose of the results' final error."""
    t = np.arange(751) * 0.02
    frames = nearest_periods(t, 25.0)
    assert frames[:4].tolist() == [0, 2, 4, 6] and frames[-1] == 750
    odd = np.arange(10) * 0.03  # frames between periods: the nearer one
    assert nearest_periods(odd, 25.0).tolist() == [0, 1, 3, 4, 5, 7, 8, 9]
    assert nearest_periods(np.array([0.0]), 25.0).tolist() == [0]


@pytest.mark.slow
def test_still_needs_html_and_a_period_of_the_trial(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", "quick", "--out", str(out), "--trials", "1", "--record", "1",
                     "--controllers", "leg-edge", "--max-steps", "10", "--no-progress"]) == 0
    capsys.readouterr()
    viz = ["viz", str(out), "--trial", "0", "--controller", "leg-edge"]
    assert cli_main([*viz, "--still", "3"]) == 2  # (it started the live view, exit 0)
    assert "--still draws a still into the --html page" in capsys.readouterr().err
    page = tmp_path / "new" / "folder" / "t.html"
    assert cli_main([*viz, "--still", "5000", "--html", str(page)]) == 2  # (period 5000 % n)
    err = " ".join(capsys.readouterr().err.split())
    assert "--still 5000:" in err and "has periods 0 to" in err and not page.exists()
    assert cli_main([*viz, "--still", "-1", "--html", str(page)]) == 0  # its folder made
    assert page.exists() and page.with_suffix(".png").exists()


@pytest.mark.slow
def test_the_page_and_its_curves_name_the_sweep_point(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A record of sweep point 1 was titled as one of point 0 (scenario / controller /
    trial), and the page's title was 'MeshCat'."""
    out = tmp_path / "run"
    assert cli_main(["run", "andreff2006-front-camera", "--out", str(out), "--trials", "1",
                     "--record", "1", "--controllers", "leg-edge", "--max-steps", "5",
                     "--no-progress"]) == 0
    capsys.readouterr()
    page = tmp_path / "p1.html"
    assert cli_main(["viz", str(out), "--trial", "0", "--point", "1", "--html",
                     str(page)]) == 0
    said = capsys.readouterr().out
    assert said.startswith("andreff2006-front-camera / sweep point 1 / leg-edge / trial 0")
    assert ("<title>andreff2006-front-camera / sweep point 1 / leg-edge / trial 0</title>"
            in page.read_text())
