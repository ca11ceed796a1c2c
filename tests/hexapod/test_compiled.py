"""The first compilation of a C kernel says so, once per process (a cold cache waits
tens of seconds); a cached kernel says nothing."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from hexapod import compiled

MESSAGE = "compiling the controllers' C kernels (first run only, ~30 s"


def test_first_compilation_is_announced_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setenv("HEXAPOD_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled, "_ANNOUNCED", False)
    with caplog.at_level(logging.WARNING, logger="hexapod.compiled"):
        compiled.build_shared_library("one", "int one(void) { return 1; }\n")
        compiled.build_shared_library("two", "int two(void) { return 2; }\n")
    said = [r.getMessage() for r in caplog.records if MESSAGE in r.getMessage()]
    assert said == [f"{MESSAGE}; cached in {tmp_path})"]
    caplog.clear()
    monkeypatch.setattr(compiled, "_ANNOUNCED", False)  # a new process, a warm cache
    with caplog.at_level(logging.WARNING, logger="hexapod.compiled"):
        compiled.build_shared_library("one", "int one(void) { return 1; }\n")
    assert not caplog.records
