"""Checks of what a scenario file names, in the file's terms: the files it references
(relative to the scenario file) and the options of its controllers (against each
controller's signature)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario_model import ControllerSpec
from hexapod.config import suggest


def referenced_file(base_dir: Path, value: str, key: str, path: str) -> str:
    """The path of a file a scenario names (relative to the scenario file's folder).

    Raises:
        ScenarioError: The file does not exist: naming the key, the full path tried and
            the rule for relative paths.
    """
    target = base_dir / value
    if not target.is_file():
        rule = ("" if Path(value).is_absolute() else
                f" (a relative path is relative to the folder of the scenario file, "
                f"{base_dir.resolve()})")
        what = "is a folder, not a file" if target.is_dir() else "file not found"
        raise ScenarioError(path, f"{value!r}: {what}: tried {target.resolve()}{rule}",
                            key=key)
    return str(target)


def check_option_names(source: str, spec: ControllerSpec, factory: Any, where: str) -> None:
    """Every option of ``spec`` is a parameter of the controller's factory (its signature).

    Raises:
        ScenarioError: An option the controller does not take, naming the key as written
            in the file, the controller's options and the close one.
    """
    import inspect

    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):  # no signature to check against (a C callable)
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    accepted = [n for n, p in params.items()
                if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD,
                              inspect.Parameter.KEYWORD_ONLY)]
    for option in spec.options:
        if option not in accepted:
            key = spec.option_keys.get(option, f"{where}.{option}")
            raise ScenarioError(
                source, f"controller '{spec.name}' has no option '{option}'; its options: "
                f"{', '.join(accepted) or 'none'}", key=key,
                suggestion=suggest(option, accepted))
