"""Exceptions of the :mod:`benchmarks` package."""

from __future__ import annotations

from typing import Any

from hexapod.error_base import PicklableError
from hexapod.exceptions import ConfigFileError


class BenchmarkError(PicklableError):
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


class DirectoryLockedError(ResultsError):
    """Another run holds the results directory (one run writes into a directory at a time).

    Attributes:
        path: The results directory.
        pid: Process id of the run that holds it (None if it could not be read).
        holder: What that run wrote into the lock file (its command and start time).
    """

    def __init__(self, path: str, pid: int | None, holder: str) -> None:
        self.pid = pid
        self.holder = holder
        who = f"PID {pid}" if pid is not None else "an unknown process"
        super().__init__(path, f"another hexapod-bench run ({who}: {holder or '?'}) is "
                         "writing into this directory; wait for it to finish (or stop it), "
                         "or choose another --out")


class ForeignCalibrationError(ScenarioError):
    """A calibration file was made with another robot or camera than the one it is used
    with (its ``[made_with]`` table names both and their fingerprints)."""


class SetupError(BenchmarkError):
    """A study whose every trial would fail the same way, refused before its first trial.

    Attributes:
        source: The scenario file.
        problems: The errors found (:class:`~benchmarks.study.setup_check.Problem`: each
            has a ``text``).
    """

    def __init__(self, source: str, problems: list[Any]) -> None:
        self.source = source
        self.problems = problems
        text = "; ".join(p.text for p in problems)
        super().__init__(f"{source}: the setup cannot run, every trial would fail: {text} "
                         f"(hexapod-bench check {source} shows the details)")


def user_message(exc: BaseException) -> str:
    """One line in the user's terms for the exception that ended a trial (a failure
    row's ``cause``).

    The known causes of a setup that cannot work are translated into what to change in
    which file; any other exception keeps its own message, prefixed by its type when it
    is not one of the project's (a bug, or a plugin's error).
    """
    import math

    from controllers.exceptions import ContextError, ControllerError
    from hexapod.exceptions import HexapodError, WorkspaceError
    from vision.exceptions import VisionError

    if isinstance(exc, WorkspaceError):
        return (f"no start or goal pose: only {exc.found} of {exc.attempts} random poses "
                f"(within {exc.max_translation * 1e3:g} mm and "
                f"{math.degrees(exc.max_angle):g} deg of the home pose) keep every leg "
                f"{exc.margin * 1e3:g} mm inside its stroke; change stroke_mm in the robot "
                "file, or [task] max_translation_mm, max_angle_deg or margin_mm in the "
                "scenario")
    if isinstance(exc, ContextError) and exc.field.startswith("goal"):
        if "desired direction" in exc.problem:
            seen = ("the camera sees both edges of no leg at the goal pose (a leg's direction "
                    "needs both)")
        elif "visible desired edge" in exc.problem:
            seen = "the camera sees no leg edge at the goal pose"
        else:
            seen = ""
        if seen:
            return (f"{seen}, so there is no desired image to servo to; move the camera "
                    "([camera] in the scenario, or [camera_from_base] in the camera file) so "
                    "that it sees the legs (hexapod-bench check shows what it sees)")
    if isinstance(exc, HexapodError | VisionError | ControllerError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


class StudyMismatchError(ResultsError):
    """A run into a directory that holds another study (``run --resume`` with another
    seed, world, controllers, scenario content or trial plan), refused before any trial.

    Attributes:
        path: The run directory.
        differences: Each difference in words (``--seed: 1 in the directory, 99 given``).
    """

    def __init__(self, path: str, differences: list[str]) -> None:
        self.differences = differences
        listed = "".join(f"\n  {d}" for d in differences)
        super().__init__(path, "holds another study than the one given (a run directory "
                         f"holds one study; nothing was run):{listed}\nrun the given study "
                         "into another --out, or give the directory's settings (its "
                         "command lines are in run.json and report.md)")


class ClusterError(BenchmarkError):
    """The Dask cluster of a run failed under it (its scheduler gone, a unit's workers
    killed again and again): the rows written stay, and ``--resume`` finishes the run.

    Attributes:
        cause: What Dask raised.
    """

    def __init__(self, cause: BaseException) -> None:
        self.cause = cause
        super().__init__(f"the Dask cluster failed ({type(cause).__name__}: {cause})")


class BatchFailedError(BenchmarkError):
    """A batch of trials stopped as a whole (the controller's ``step_batch`` raised, or
    returned commands of the wrong shape or kind); each trial of it gets a failure row
    saying so, with the step and its last errors (it is not rerun).

    Attributes:
        step: The period at which it happened.
        errors: The last position [m] and orientation [rad] errors of each row.
        cause: The exception.
    """

    def __init__(self, step: int, errors: tuple[Any, Any], cause: BaseException) -> None:
        self.step = step
        self.errors = errors
        self.cause = cause
        super().__init__(f"at step {step}: {type(cause).__name__}: {cause}")


class FigureFileError(BenchmarkError):
    """The declared paper figures (``hexapod-bench reproduce``) are invalid.

    Attributes:
        path: The declared-figures file.
        row: The row (its ``id``, or ``figure[INDEX]`` before the id is known).
        key: The offending key (None for the row as a whole).
        problem: What is wrong, with the value.
    """

    def __init__(self, path: str, row: str, key: str | None, problem: str) -> None:
        self.path = path
        self.row = row
        self.key = key
        self.problem = problem
        where = f"{row}.{key}" if key else row
        super().__init__(f"{path}: {where}: {problem}")
