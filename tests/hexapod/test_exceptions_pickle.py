"""The project's errors cross process boundaries whole: pickled and loaded (as a process
pool or Dask returns a worker's error), each keeps its type, message and attributes
(the default pickle called ``cls(message)``, which an ``__init__`` of other parameters
refuses: a worker's ``ConfigFileError`` broke ``warm``'s pool)."""

from __future__ import annotations

import importlib
import inspect
import pickle

import pytest

MODULES = ("hexapod.exceptions", "hexapod.link_errors", "benchmarks.exceptions",
           "controllers.exceptions", "vision.exceptions")


def _sample(name: str) -> object:
    """A value for a required parameter, by its name."""
    if name in ("leg", "pid", "code", "step", "count", "n", "index"):
        return 3
    if name in ("value", "lower", "upper", "seconds", "timeout", "timeout_s", "residual",
                "tolerance", "expected", "elapsed"):
        return 0.5
    if name in ("available", "known", "differences", "lines"):
        return ["a", "b"]
    return "text"


def _errors() -> list[type[BaseException]]:
    out = []
    for mod in MODULES:
        m = importlib.import_module(mod)
        out += [c for c in vars(m).values() if inspect.isclass(c)
                and issubclass(c, BaseException) and c.__module__ == mod]
    return out


def test_every_error_of_the_project_round_trips_through_pickle() -> None:
    done = []
    for cls in _errors():
        params = [p for p in list(inspect.signature(cls.__init__).parameters.values())[1:]
                  if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY,
                                                         p.POSITIONAL_OR_KEYWORD)]
        try:
            exc = cls(*[_sample(p.name) for p in params])
        except (TypeError, ValueError, AttributeError):
            continue  # a parameter this generic sample does not fit (some below)
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is cls and str(back) == str(exc), cls
        assert vars(back) == vars(exc), cls
        done.append(cls.__name__)
    assert len(done) >= 55, done  # (of 64 classes)


def test_a_config_error_keeps_its_fields_through_a_process_pool() -> None:
    import concurrent.futures as cf

    from hexapod.exceptions import ConfigFileError

    with cf.ProcessPoolExecutor(1) as pool, pytest.raises(ConfigFileError) as info:
        pool.submit(_raise_config_error).result()
    assert info.value.path == "robot.toml" and info.value.key == "stroke_mm"
    assert "robot.toml: key 'stroke_mm': expected 2 numbers" in str(info.value)


def _raise_config_error() -> None:
    from hexapod.exceptions import ConfigFileError

    raise ConfigFileError("robot.toml", "expected 2 numbers", key="stroke_mm")
