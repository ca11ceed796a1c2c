"""The declared search spaces of ``hexapod-bench tune`` (``docs/tuning.md``): which gain
options of a controller are searched, over which range, and the candidates every
controller gets, the same number for each.

A search space is data (:data:`SEARCH_SPACE`, or a ``--space FILE`` that replaces it):
per *family* of controllers, the axes (an option, its range, linear or logarithmic, and
for a vector option the shape it scales). A controller belongs to the first family one
of whose options it declares (:func:`controllers.options.option_table`); an axis whose
option the controller does not take is skipped with a message naming it (a space file's
axis, or a plug-in computed-torque law without ``integral_gain``).

The candidates of a controller (:func:`candidates`): number 0 is the options as given
(the scenario's, so a tuned controller is never worse than the given one on the tuning
trials), then ``n - 1`` points of the space: evenly spaced (in the axis' scale) for one
axis, the first points of a Halton sequence for several.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import ScenarioError
from hexapod.config import suggest

#: How an axis is sampled.
SCALES = ("log", "linear")


@dataclass(frozen=True)
class Axis:
    """One searched option.

    Attributes:
        option: The controller option (``controllers/options.py``'s table).
        low: Smallest value of the searched scalar (in the option's unit).
        high: Largest value (``>= low``).
        scale: ``"log"`` (evenly spaced logarithms; ``low > 0``) or ``"linear"``.
        shape: For a vector option, the value is the scalar times this vector
            (``adaptive_gain = x (1, 0.2, 6)``: ``lambda0 = x``, ``lambda_inf = x / 5``,
            ``lambda0' = 6 x``); None: a scalar option.
        unit: The unit of the scalar, for the messages and the docs.
    """

    def at_end(self, value: Any) -> bool:
        """Whether an option's value is at an end of the range (its scalar at ``low`` or
        ``high``, to 1e-6 relative)."""
        x = value[0] / self.shape[0] if self.shape is not None else value
        return any(math.isclose(float(x), b, rel_tol=1e-6, abs_tol=1e-12)
                   for b in (self.low, self.high))

    option: str
    low: float
    high: float
    scale: str = "log"
    shape: tuple[float, ...] | None = None
    unit: str = ""

    def value(self, u: float) -> Any:
        """The option's value at ``u`` in [0, 1] along the axis (rounded to 6
        significant digits, so that the options file reads as written)."""
        if self.scale == "log":
            x = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            x = self.low + u * (self.high - self.low)
        x = float(f"{x:.6g}")
        if self.shape is None:
            return x
        return [float(f"{x * s:.6g}") for s in self.shape]


#: The declared search spaces, by family (``docs/tuning.md``). Velocity laws (the vision
#: laws, their QP and predictive variants, joint-space, model-based): the adaptive gain
#: of ``docs/math.md`` section 6 with the shape of quick's ``[5, 1, 30]``, its
#: ``lambda0`` from 1 to 50 1/s (50 = ``1 / dt`` at 20 ms: the discrete loop's deadbeat
#: gain; above it the error overshoots every period, unstable at ``2 / dt``). Computed torque
#: (joint, Cartesian, feature space): the closed loop's natural frequency from 0.5 to
#: 16 Hz (``omega_n dt`` up to 2 at 20 ms) and the integral gain from 0 to 4 1/s (every
#: built-in computed-torque law takes it; a plug-in law without it has the axis
#: skipped). The upper ends were widened after a first tuning of ``inertia-error``
#: chose the old ones (20 1/s, 8 Hz): a chosen value at an end of its range says the
#: range may be too narrow (``tune`` warns).
SEARCH_SPACE: dict[str, tuple[Axis, ...]] = {
    "velocity": (Axis("adaptive_gain", 1.0, 50.0, "log", (1.0, 0.2, 6.0), "1/s"),),
    "computed-torque": (Axis("natural_frequency", 0.5, 16.0, "log", unit="Hz"),
                        Axis("integral_gain", 0.0, 4.0, "linear", unit="1/s")),
}


@dataclass(frozen=True)
class ControllerSpace:
    """The search space of one controller.

    Attributes:
        label: The controller's label in the study.
        family: Its family (None: none of the space's families applies).
        axes: The axes it takes.
        skipped: Messages for the axes it does not take.
    """

    label: str
    family: str | None
    axes: tuple[Axis, ...]
    skipped: tuple[str, ...] = ()


def controller_space(label: str, name: str, table: Any,
                     space: dict[str, tuple[Axis, ...]],
                     own: frozenset[str] = frozenset()) -> ControllerSpace:
    """The axes of ``space`` a controller takes.

    Args:
        label: The controller's label.
        name: Its registry name.
        table: Its :class:`~controllers.options.OptionTable`.
        space: The search space (by family, or by label / registry name for a space
            file's own tables: those come first).
        own: The tables that belong to a controller of the tuning (its label or name):
            never another's family (a range set for leg-edge was searched by every
            controller that takes its option).
    """
    def takes(option: str) -> bool:
        return bool(table.declares(option))

    for family in (label, name):  # a space file's table for this very controller
        if family in space:
            return _split(label, family, space[family], takes, name, table)
    for family, axes in space.items():
        if family not in own and any(takes(a.option) for a in axes):
            return _split(label, family, axes, takes, name, table)
    return ControllerSpace(label, None, (), (
        f"{label}: no family of the search space applies (its options: "
        f"{', '.join(table.names) or 'none'}): only its options as given are evaluated",))


def _split(label: str, family: str, axes: tuple[Axis, ...], takes: Any, name: str,
           table: Any) -> ControllerSpace:
    kept = tuple(a for a in axes if takes(a.option))
    skipped = tuple(f"{label}: option '{a.option}' of the search space ({family}) is skipped: "
                    f"controller '{name}' does not take it (its options: "
                    f"{', '.join(table.names) or 'none'})"
                    for a in axes if not takes(a.option))
    return ControllerSpace(label, family, kept, skipped)


def candidates(given: dict[str, Any], axes: tuple[Axis, ...], n: int) -> list[dict[str, Any]]:
    """The ``n`` candidate option sets of a controller: the options as given, then
    ``n - 1`` points of its axes (see the module docstring). Without an axis, the
    options as given alone.

    Raises:
        ValueError: ``n < 2``.
    """
    if n < 2:
        raise ValueError(f"at least 2 candidates (the options as given and one searched), "
                         f"got {n}")
    out = [dict(given)]
    if not axes:
        return out
    m = n - 1
    if len(axes) == 1:
        points = np.linspace(0.0, 1.0, m)[:, None] if m > 1 else np.full((1, 1), 0.5)
    else:
        points = halton(m, len(axes))
    for u in points:
        opts = dict(given)
        for axis, x in zip(axes, u, strict=True):
            opts[axis.option] = axis.value(float(x))
        out.append(opts)
    return out


_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29)


def halton(n: int, d: int) -> np.ndarray:
    """The points 1 to ``n`` of the unscrambled Halton sequence in ``[0, 1)^d`` (bases
    the first ``d`` primes; point 0, the origin, left out), (n, d)."""
    if d > len(_PRIMES):
        raise ValueError(f"at most {len(_PRIMES)} axes, got {d}")
    out = np.zeros((n, d))
    for j, base in enumerate(_PRIMES[:d]):
        for i in range(n):
            k, f, x = i + 1, 1.0, 0.0
            while k:
                f /= base
                x += f * (k % base)
                k //= base
            out[i, j] = x
    return out


def _number(value: Any, path: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(path, f"expected a finite number, got {value!r}", key=key)
    return float(value)


AXIS_KEYS = ("low", "high", "scale", "shape", "unit")


def parse_axis(option: str, table: Any, path: str, where: str) -> Axis:
    """One axis of a space file (``option = {low = .., high = .., scale = "log"}``).

    Raises:
        ScenarioError: Naming the file and key: an unknown key, a missing bound, a range
            with ``low > high``, a log scale with ``low <= 0``, an unknown scale.
    """
    key = f"{where}.{option}"
    if not isinstance(table, dict):
        raise ScenarioError(path, "expected a table {low = .., high = .., scale = \"log\"}, "
                            f"got {table!r}", key=key)
    for k in table:
        if k not in AXIS_KEYS:
            raise ScenarioError(path, f"unknown key '{k}' (an axis has {', '.join(AXIS_KEYS)})",
                                key=f"{key}.{k}", suggestion=suggest(k, AXIS_KEYS))
    for k in ("low", "high"):
        if k not in table:
            raise ScenarioError(path, "missing (an axis needs low and high)", key=f"{key}.{k}")
    low = _number(table["low"], path, f"{key}.low")
    high = _number(table["high"], path, f"{key}.high")
    scale = table.get("scale", "log")
    if scale not in SCALES:
        raise ScenarioError(path, f"expected one of {', '.join(SCALES)}, got {scale!r}",
                            key=f"{key}.scale")
    if low > high:
        raise ScenarioError(path, f"low {low:g} is above high {high:g}", key=key)
    if scale == "log" and low <= 0:
        raise ScenarioError(path, f"a log scale needs low > 0, got {low:g}", key=f"{key}.low")
    shape = table.get("shape")
    if shape is not None:
        if not isinstance(shape, list) or not shape:
            raise ScenarioError(path, f"expected a list of numbers, got {shape!r}",
                                key=f"{key}.shape")
        shape = tuple(_number(s, path, f"{key}.shape") for s in shape)
    unit = table.get("unit", "")
    return Axis(option, low, high, scale, shape, str(unit))


def load_space(path: str | Path) -> dict[str, tuple[Axis, ...]]:
    """A search space from a TOML file: one table per family, controller label or
    registry name, each holding its axes::

        [velocity]
        adaptive_gain = { low = 1.0, high = 20.0, scale = "log", shape = [1.0, 0.2, 6.0] }

        ["leg-edge"]
        gain = { low = 0.5, high = 8.0 }

    Raises:
        ScenarioError: The file cannot be read, or an axis is malformed (naming the key).
    """
    p = str(path)
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ScenarioError(p, f"file not found: tried {Path(path).resolve()}") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ScenarioError(p, f"cannot be read as TOML: {exc}") from None
    out: dict[str, tuple[Axis, ...]] = {}
    for family, axes in data.items():
        if not isinstance(axes, dict) or not axes:
            raise ScenarioError(p, "expected a table of axes (option = {low = .., high = ..})",
                                key=family)
        out[family] = tuple(parse_axis(option, t, p, family) for option, t in axes.items())
    return out


def check_space_options(space: dict[str, tuple[Axis, ...]], tables: dict[str, Any],
                        names: dict[str, str], path: str) -> frozenset[str]:
    """A space FILE's table for one controller (by label or name) names options that
    controller takes: an option it does not is an error (a typo), not a skip.

    Args:
        space: The file's space.
        tables: Each label's option table.
        names: Each label's registry name.
        path: The file (for the message).

    Returns:
        The keys that are the controllers' own tables (their labels and names).

    Raises:
        ScenarioError: Naming the file, the key, the controller's options and the close
            one.
    """
    own = frozenset(names) | frozenset(names.values())
    for key, axes in space.items():  # a family's table: options some controller takes
        if key in own:
            continue
        close = suggest(key, own)
        if close is not None and key not in SEARCH_SPACE:  # (a controller's, misspelt)
            raise ScenarioError(path, f"table [{key}] is no controller of this tuning "
                                f"({', '.join(sorted(names))}) and no family of the built-in "
                                f"space ({', '.join(SEARCH_SPACE)})", key=key,
                                suggestion=close)
        for axis in axes:
            if not any(tables[label].declares(axis.option) for label in names):
                every = sorted({o for label in names for o in tables[label].names})
                raise ScenarioError(
                    path, f"no controller of this tuning ({', '.join(sorted(names))}) has an "
                    f"option '{axis.option}'; their options: {', '.join(every) or 'none'}",
                    key=f"{key}.{axis.option}", suggestion=suggest(axis.option, every))
    for label, name in names.items():
        for key in (label, name):
            for axis in space.get(key, ()):
                table = tables[label]
                if not table.declares(axis.option):
                    raise ScenarioError(
                        path, f"controller '{name}' has no option '{axis.option}'; its options: "
                        f"{', '.join(table.names) or 'none'} (hexapod-bench list --options "
                        f"{name})", key=f"{key}.{axis.option}",
                        suggestion=suggest(axis.option, table.names))
    return own
