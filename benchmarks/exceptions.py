"""Exceptions of the :mod:`benchmarks` package."""

from __future__ import annotations

from hexapod.exceptions import ConfigFileError


class BenchmarkError(Exception):
    """Base class of every error raised by :mod:`benchmarks`."""


class ScenarioError(ConfigFileError, BenchmarkError):
    """A scenario file is invalid: names the file, the key and what was expected."""


class ResultsError(BenchmarkError):
    """A results directory is missing, unreadable or inconsistent.

    Attributes:
        path: The file or directory.
        problem: What is wrong.
    """

    def __init__(self, path: str, problem: str) -> None:
        self.path = path
        self.problem = problem
        super().__init__(f"{path}: {problem}")
