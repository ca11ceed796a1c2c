"""A plugin feature's controllers against the built-in leg-edge laws with the same solver
(``python -m benchmarks.perf.features [MODULE]``).

``MODULE`` holds ``JOINTS = controllers_for(feature)`` (:func:`controllers.features.
controllers_for`; default: the worked example of ``docs/plugins.md``,
``tests.controllers.plugin_feature_joints``, importable from the repository's root).
Its ``pinv``, ``qp``, ``mpc`` and ``ctc`` controllers are timed in ONE run of
:func:`benchmarks.perf.controllers.time_controllers` (interleaved, the same
observations) beside ``leg-edge``, ``leg-edge-qp``, ``leg-edge-mpc`` and
``leg-edge-ctc``; the table gives each pair's medians and their ratio, which the issue
asks to be at most 1.5 (``LIMIT``).
"""

from __future__ import annotations

import argparse
import sys

from benchmarks.perf import check_counts, seed
from benchmarks.perf.controllers import StepTiming, time_controllers

#: Default module of the plugin feature (the worked example).
EXAMPLE = "tests.controllers.plugin_feature_joints"
#: The built-in law of each solver.
BUILT_IN = {"pinv": "leg-edge", "qp": "leg-edge-qp", "mpc": "leg-edge-mpc",
            "ctc": "leg-edge-ctc"}
#: Highest plugin/built-in ratio of the medians asked for.
LIMIT = 1.5


def compare(module: str = EXAMPLE, attr: str = "JOINTS", steps: int = 3000,
            seed: int = 0) -> list[tuple[str, StepTiming, StepTiming]]:
    """``(solver, built-in timing, plugin timing)`` for each solver, one run."""
    plugin = {solver: f"{module}:{attr}.{solver}" for solver in BUILT_IN}
    names = [n for solver in BUILT_IN for n in (BUILT_IN[solver], plugin[solver])]
    timings = {t.name: t for t in time_controllers(names, steps, seed=seed)}
    return [(solver, timings[BUILT_IN[solver]], timings[plugin[solver]])
            for solver in BUILT_IN]


def format_comparison(rows: list[tuple[str, StepTiming, StepTiming]]) -> str:
    """A plain-text table."""
    lines = [f"{'solver':<7} {'built-in':<14} {'median us':>10} {'plugin us':>10} "
             f"{'ratio':>6} {'refused':>8}  (limit {LIMIT})"]
    for solver, ref, own in rows:
        ratio = own.median_us / ref.median_us
        lines.append(f"{solver:<7} {ref.name:<14} {ref.median_us:>10.1f} "
                     f"{own.median_us:>10.1f} {ratio:>6.2f} {own.refused:>8}"
                     f"{'' if ratio <= LIMIT else '  OVER'}")
    return "\n".join(lines)


def _kind(value: object) -> str:
    """What ``value`` is, in a message (``a class``, ``a dict``)."""
    return "a class" if isinstance(value, type) else f"a {type(value).__name__}"


def _check_attr(parser: argparse.ArgumentParser, module: str, attr: str) -> None:
    """Refuse a MODULE that does not import or an ``--attr`` that is not a
    ``controllers_for(...)`` result of it, in the options' words (it was reported as a
    controller plugin of ``--controllers`` that failed to load)."""
    import importlib

    from controllers.features import FeatureControllers

    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        parser.error(f"MODULE {module!r} cannot be imported: {exc}")
    value = getattr(mod, attr, None)
    if not isinstance(value, FeatureControllers):
        found = sorted(k for k, v in vars(mod).items() if isinstance(v, FeatureControllers))
        what = (f"{module} has no attribute {attr!r}" if value is None else
                f"{module}.{attr} is {_kind(value)}, not a controllers_for(...) "
                "result")
        parser.error(f"--attr {attr}: {what}; its controllers_for(...) results: "
                     f"{', '.join(found) or 'none'}")


def main(argv: list[str] | None = None) -> int:
    """Print the comparison; exit 1 when a ratio is over :data:`LIMIT` or a plugin step
    was refused."""
    parser = argparse.ArgumentParser(prog="hexapod-bench perf features",
                                     description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("module", nargs="?", default=EXAMPLE,
                        help=f"module holding the feature's controllers (default {EXAMPLE})")
    parser.add_argument("--attr", default="JOINTS",
                        help="its controllers_for(...) result (default JOINTS)")
    parser.add_argument("--steps", type=int, default=3000,
                        help="steps per controller (default 3000)")
    parser.add_argument("--seed", type=seed, default=0,
                        help="random seed of the observations (default 0)")
    args = parser.parse_args(argv)
    check_counts(parser, args, "--steps")
    _check_attr(parser, args.module, args.attr)
    rows = compare(args.module, args.attr, args.steps, args.seed)
    sys.stdout.write(format_comparison(rows) + "\n")
    ok = all(own.median_us <= LIMIT * ref.median_us and own.refused == 0
             for _, ref, own in rows)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
