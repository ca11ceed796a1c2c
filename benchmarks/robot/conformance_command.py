"""``hexapod-bench conformance BACKEND_SPEC``: the backend conformance check
(:func:`hexapod.backends.conformance.check_backend`) from the command line: the backend
and the exact simulator driven with the same commands, the figures of
:class:`~hexapod.backends.conformance.ConformanceReport` printed. It drives the legs
through their whole stroke at ten times the speed limit: on real hardware only with
``--move-real-robot``.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.models import add_robot_arguments, check_dt, check_option, robot_geometry

#: Default tolerance on the measured lengths [um]: the serial protocol carries
#: micrometres (the emulator drifts 3.5 um from the exact simulator over 50 periods).
DEFAULT_TOLERANCE_UM = 10.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of ``hexapod-bench conformance`` to a parser."""
    p.add_argument("backend", metavar="BACKEND_SPEC",
                   help="the backend to check: emulator, gcs-emulator, sim, serial:URL, "
                        "gcs:tcp://HOST:PORT, a plugin's NAME[:ARGS] or module:attr[:ARGS]")
    add_robot_arguments(p)
    p.add_argument("--tolerance-um", type=float, default=DEFAULT_TOLERANCE_UM, metavar="UM",
                   help="largest allowed deviation of the measured lengths from the "
                        f"simulator's over the smooth motion [um] (default "
                        f"{DEFAULT_TOLERANCE_UM:g})")
    p.add_argument("--periods", type=int, default=25,
                   help="periods of the smooth motion (default 25)")
    p.add_argument("--move-real-robot", action="store_true",
                   help="run on real hardware: the check drives the legs through their "
                        "whole stroke")


def run(args: argparse.Namespace) -> int:
    """Run the check and print its figures; returns the exit code (0 pass, 1 fail).

    Raises:
        BenchmarkError: A bad option, or real hardware without ``--move-real-robot``.
        UnknownBackendError, BackendPluginError: A bad spec.
    """
    from hexapod.backends.conformance import check_backend
    from hexapod.backends.registry import backends

    check_option("--tolerance-um", args.tolerance_um, strict=False, finite=True)
    check_dt(args.dt)
    check_option("--periods", args.periods, 1, strict=False)
    name = backends.check(args.backend)
    if not backends.is_simulated(args.backend) and not args.move_real_robot:
        raise BenchmarkError(f"{args.backend} is real hardware: the check drives its legs "
                             "through their whole stroke; add --move-real-robot to run it")
    geometry = robot_geometry(args.geometry)

    def factory(g: object, q: np.ndarray) -> object:
        return backends.open(args.backend, geometry, q)

    tol = args.tolerance_um * 1e-6
    report = check_backend(factory, geometry, args.dt, tol, args.periods)  # type: ignore[arg-type]
    verdict = "PASS" if report.ok else "FAIL"
    missed = (f", {report.missed_periods} missed by the host and not compared"
              if report.missed_periods else "")
    print(f"conformance of {args.backend} ({name}) against the simulator, {geometry.name}, "
          f"dt {args.dt * 1e3:g} ms: {report.periods} periods; largest deviation over the "
          f"smooth motion {report.max_deviation * 1e6:.3f} um (tolerance "
          f"{args.tolerance_um:g} um){missed}: {verdict}")
    for problem in report.problems:
        print(f"  - {problem}")
    return 0 if report.ok else 1
