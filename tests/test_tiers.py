"""The test tiers: `make quick` fails an unmarked test over its budget (tests/conftest.py),
so that the quick tier stays quick; markers are strict."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CASES = '''
import time

import pytest


def test_fast():
    pass


def test_unmarked_but_slow():
    time.sleep(0.6)


@pytest.mark.slow
def test_marked_slow():
    time.sleep(0.6)
'''


def _pytest(folder: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-p", "no:xdist", *args], cwd=folder, capture_output=True, text=True,
                          timeout=120, check=False)


@pytest.fixture
def suite(tmp_path: Path) -> Path:
    """This suite's conftest.py and pytest settings beside three small tests."""
    root = Path(__file__).resolve().parents[1]
    shutil.copy(root / "tests" / "conftest.py", tmp_path / "conftest.py")
    shutil.copy(root / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / "test_cases.py").write_text(CASES)
    return tmp_path


@pytest.mark.slow
def test_budget_fails_only_unmarked_slow_tests(suite: Path) -> None:
    proc = _pytest(suite, "--rootdir", str(suite), "test_cases.py", "--unmarked-budget", "0.3")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "1 failed, 2 passed" in proc.stdout
    assert "test_unmarked_but_slow took" in proc.stdout
    assert "over the quick tier's budget of 0.3 s" in proc.stdout


@pytest.mark.slow
def test_no_budget_and_quick_selection(suite: Path) -> None:
    proc = _pytest(suite, "--rootdir", str(suite), "test_cases.py")
    assert proc.returncode == 0 and "3 passed" in proc.stdout, proc.stdout + proc.stderr
    proc = _pytest(suite, "--rootdir", str(suite), "test_cases.py", "-m", "not slow")
    assert proc.returncode == 0 and "2 passed, 1 deselected" in proc.stdout, proc.stdout


@pytest.mark.slow
def test_unknown_marker_is_an_error(suite: Path) -> None:
    (suite / "test_typo.py").write_text("import pytest\n\n\n@pytest.mark.slwo\ndef test_x():\n"
                                        "    pass\n")
    proc = _pytest(suite, "--rootdir", str(suite), "test_typo.py")
    assert proc.returncode != 0 and "'slwo' not found in `markers`" in proc.stdout + proc.stderr
