"""Controller options: the table each controller declares (:func:`option_table`, read by
the scenario checks and ``hexapod-bench list --options``), and controllers that remember
the options they were built with.

A controller steps each trial of a batch with its own instance where it computes no
rows as arrays (:class:`controllers.base.Controller`); those instances are built from the
options of the batch's own instance, never copied from it (a copy would carry whatever
state it holds).
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass
from typing import Any, TypeVar

T = TypeVar("T", bound="RemembersOptions")


class RemembersOptions:
    """Records the constructor's arguments; :meth:`clone` builds an un-reset twin."""

    _options: tuple[tuple[Any, ...], dict[str, Any]]

    def __new__(cls, *args: Any, **kwargs: Any) -> Any:
        obj = super().__new__(cls)
        obj._options = (args, dict(kwargs))
        return obj

    def clone(self: T) -> T:
        """A new instance with the same options, not reset."""
        args, kwargs = self._options
        return type(self)(*args, **kwargs)


#: A constructor parameter without a default (the option must be given).
REQUIRED = object()

#: Options that choose the same thing in different ways (``adaptive_gain`` replaces
#: ``gain``): a controller's own table giving one of a group takes that choice over a
#: scenario's ``[controller_options]`` giving another, and its table may give only one.
ALTERNATIVE_OPTIONS: tuple[frozenset[str], ...] = (frozenset({"gain", "adaptive_gain"}),)


@dataclass(frozen=True)
class OptionSpec:
    """One option of a controller: what ``list --options`` prints and what the scenario
    checks accept.

    Attributes:
        name: The keyword (the scenario key).
        type: Its type, as written in the signature (``"float"``).
        default: The default value (:data:`REQUIRED`: none, the option must be given).
        unit: The SI unit (``"1/s"``; empty when dimensionless or not stated).
        meaning: One sentence saying what it does.
    """

    name: str
    type: str = ""
    default: Any = None
    unit: str = ""
    meaning: str = ""

    def __post_init__(self) -> None:
        if isinstance(self.type, type):  # OptionSpec("gain", float, ...): its name
            object.__setattr__(self, "type", self.type.__name__)
        elif not isinstance(self.type, str):
            raise TypeError(f"OptionSpec {self.name!r}: type must be a name (\"float\") or a "
                            f"type (float), got {self.type!r}")


@dataclass(frozen=True)
class OptionTable:
    """The options a controller factory declares.

    Attributes:
        options: The declared options, in signature order.
        open: The factory also takes options it hands on (a ``**options`` parameter:
            a wrapped law's); names outside ``options`` are checked when it is built.
        passes_on: What the ``**`` parameter's docstring says it takes (empty: unknown).
    """

    options: tuple[OptionSpec, ...]
    open: bool = False
    passes_on: str = ""

    @property
    def names(self) -> list[str]:
        """The declared option names."""
        return [o.name for o in self.options]

    def declares(self, name: str) -> bool:
        """``name`` is one of the declared options."""
        return name in self.names


_ARG = re.compile(r"^(\*{0,2}\w+)(?:\s*\([^)]*\))?:\s*(.*)$")
_UNIT = re.compile(r"\[([^\]]+)\]")
_UNIT_TEXT = re.compile(r"^(?:(?:1|m|mm|um|s|ms|Hz|rad|deg|px|N|kg|%)(?:\^-?\d)?[ /*]?)+$")


def first_sentence(text: str) -> str:
    """The first sentence of ``text``, reST literals and roles made plain."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"\1", text)
    text = text.replace("``", "")
    text = " ".join(text.split())
    m = re.search(r"\.(?=\s+[A-Z]|\s*$)", text)
    return text[:m.start() + 1] if m else text


def _unit(text: str) -> str:
    """The unit in square brackets of an option's first sentence (``[1/s]``), if it is
    one (``[drives]``, a section name, is not)."""
    m = _UNIT.search(text)
    if not m:
        return ""
    parts = [p.strip() for p in m.group(1).split(",")]
    return m.group(1) if all(_UNIT_TEXT.match(p) for p in parts) else ""


def docstring_args(doc: str | None) -> dict[str, str]:
    """The entries of the ``Args:`` section of a Google-style docstring, by name (each
    entry's text joined into one line)."""
    if not doc:
        return {}
    lines = inspect.cleandoc(doc).splitlines()
    out: dict[str, str] = {}
    inside = False
    indent = None
    current = None
    for line in lines:
        stripped = line.strip()
        if stripped in ("Args:", "Arguments:", "Parameters:"):
            inside, indent, current = True, None, None
            continue
        if not inside:
            continue
        if not stripped:
            continue
        level = len(line) - len(line.lstrip())
        if level == 0:  # the next section
            inside = False
            continue
        if indent is None:
            indent = level
        m = _ARG.match(stripped)
        if level == indent and m:
            current = m.group(1).lstrip("*")
            out[current] = m.group(2)
        elif current is not None and level > indent:
            out[current] += " " + stripped
    return out


def _documented(factory: Any) -> dict[str, str]:
    """The ``Args`` entries of a factory's docstrings (a class: its own, its
    ``__init__``'s and those of its bases, the nearest first)."""
    docs: list[str | None] = []
    if inspect.isclass(factory):
        for cls in factory.__mro__:
            if cls is object:
                continue
            docs += [cls.__doc__, getattr(cls.__dict__.get("__init__"), "__doc__", None)]
    else:
        docs.append(getattr(factory, "__doc__", None))
    for other in getattr(factory, "OPTION_DOCS", ()):  # where it hands options on
        docs += [other.__doc__, getattr(other, "__init__", None).__doc__]
    out: dict[str, str] = {}
    for doc in docs:
        for name, text in docstring_args(doc).items():
            out.setdefault(name, text)
    return out


def option_table(factory: Any) -> OptionTable:
    """The options of a controller factory, declared once.

    A factory may declare them itself with an ``OPTIONS`` attribute (a sequence of
    :class:`OptionSpec`); otherwise they are read from its signature (names, types,
    defaults) and the ``Args:`` section of its docstrings (meaning, the unit in square
    brackets: ``gain: Constant gain [1/s].``); a class whose options another class
    documents (a solver it builds) names it in ``OPTION_DOCS``. The scenario checks and
    ``hexapod-bench list --options`` both use this table.

    Args:
        factory: The registered factory (a class or a callable).
    """
    declared = getattr(factory, "OPTIONS", None)
    if declared is not None:
        specs = tuple(declared)
        for s in specs:
            if not isinstance(s, OptionSpec):
                raise TypeError(f"{factory!r}.OPTIONS holds {s!r}, not an OptionSpec")
        return OptionTable(specs)
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):  # no signature (a C callable): nothing to check
        return OptionTable((), open=True)
    docs = _documented(factory)
    specs_list = []
    open_ = False
    passes_on = ""
    for name, p in params.items():
        if p.kind is inspect.Parameter.VAR_KEYWORD:
            open_, passes_on = True, first_sentence(docs.get(name, ""))
            continue
        if p.kind not in (inspect.Parameter.POSITIONAL_OR_KEYWORD,
                          inspect.Parameter.KEYWORD_ONLY):
            continue
        ann = p.annotation
        type_ = ("" if ann is inspect.Parameter.empty else
                 ann if isinstance(ann, str) else getattr(ann, "__name__", str(ann)))
        meaning = first_sentence(docs.get(name, ""))
        specs_list.append(OptionSpec(
            name, type_, REQUIRED if p.default is inspect.Parameter.empty else p.default,
            _unit(meaning), meaning))
    return OptionTable(tuple(specs_list), open_, passes_on)
