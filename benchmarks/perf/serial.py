"""Round-trip time and loop rate through the serial link (``python -m benchmarks.perf.serial``).

A :class:`~hexapod.backends.serial.SerialRobot` drives the emulated controller board
(``hexapod-emulator`` on a pseudo-terminal, in a child process by default) for a
number of control periods with a joint-space proportional law towards a goal
that moves (a slow sine on each leg), exactly as a controller would. Printed per
configuration:

- the round-trip time of one exchange (command written -> checked reply read),
  median and 99th percentile, over every ``MOV`` and ``POS?`` of the run;
- the achieved loop rate (periods / wall time), the periods missed by the rate
  limiter, and the largest interval between two ``MOV`` [ms];
- the back-to-back exchange rate (``POS?`` as fast as the link answers).

``--line-rate 115200`` also emulates the transmission time of a real 115200-baud
line (10 bits a byte) in the emulator: a real board's floor.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from benchmarks.perf import check_counts, seed
from hexapod import deltalab
from hexapod.backends.emulator import FaultConfig
from hexapod.backends.serial import SerialRobot
from hexapod.backends.serial_emulated import open_emulated_robot


@dataclass
class LinkFigures:
    """What one configuration measured.

    Attributes:
        label: The configuration.
        periods: Control periods run.
        dt: Control period [s].
        rtt_median: Median exchange round trip [s].
        rtt_p99: 99th percentile exchange round trip [s].
        rtt_max: Largest exchange round trip [s].
        loop_rate: Achieved periods per second [Hz].
        missed: Periods missed (the rate limiter found itself late).
        worst_interval: Largest interval between two MOVs [s].
        step_comm: Median communication time per step (MOV + POS?) [s].
        burst_rate: Back-to-back POS? exchanges per second [Hz].
        retries: Exchanges sent again (garbled).
    """

    label: str
    periods: int
    dt: float
    rtt_median: float
    rtt_p99: float
    rtt_max: float
    loop_rate: float
    missed: int
    worst_interval: float
    step_comm: float
    burst_rate: float
    retries: int


def measure(robot: SerialRobot, label: str, periods: int, dt: float,
            burst: int = 500) -> LinkFigures:
    """Run ``periods`` control periods of ``dt`` [s] and a back-to-back burst on ``robot``."""
    q_mid = 0.5 * (robot.stroke[0] + robot.stroke[1])
    q = robot.reset(np.full(6, q_mid))
    phases = np.arange(6) * np.pi / 3
    robot.exchanges.clear()
    retried0 = robot.retried
    missed = 0
    comm = []
    mov_times = []
    t0 = time.perf_counter()
    for k in range(periods):
        goal = q_mid + 0.01 * np.sin(2 * np.pi * 0.5 * k * dt + phases)
        mov_times.append(time.perf_counter())
        st = robot.step(5.0 * (goal - q), dt)
        q = st.lengths
        missed += int(st.missed_period)
        comm.append(st.round_trip_s)
    elapsed = time.perf_counter() - t0
    rtt = np.array(robot.exchanges)
    t1 = time.perf_counter()
    for _ in range(burst):
        robot.measured_lengths()
    burst_rate = burst / (time.perf_counter() - t1)
    return LinkFigures(
        label=label, periods=periods, dt=dt,
        rtt_median=float(np.median(rtt)), rtt_p99=float(np.percentile(rtt, 99)),
        rtt_max=float(rtt.max()), loop_rate=periods / elapsed, missed=missed,
        worst_interval=float(np.max(np.diff(mov_times))) if periods > 1 else 0.0,
        step_comm=float(np.median(comm)), burst_rate=burst_rate,
        retries=robot.retried - retried0,
    )


def format_table(rows: list[LinkFigures]) -> str:
    """A Markdown table of the figures (times in ms)."""
    head = ("| configuration | periods | RTT median [ms] | RTT p99 [ms] | RTT max [ms] | "
            "comm/step [ms] | loop rate [Hz] | missed | worst MOV interval [ms] | "
            "back-to-back [Hz] | retries |")
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        lines.append(
            f"| {r.label} | {r.periods} | {r.rtt_median * 1e3:.3f} | {r.rtt_p99 * 1e3:.3f} | "
            f"{r.rtt_max * 1e3:.3f} | {r.step_comm * 1e3:.3f} | {r.loop_rate:.2f} | "
            f"{r.missed} | {r.worst_interval * 1e3:.2f} | {r.burst_rate:.0f} | {r.retries} |")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """Options of ``python -m benchmarks.perf.serial``."""
    p = argparse.ArgumentParser(prog="hexapod-bench perf serial", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--periods", type=int, default=500, help="control periods (default 500)")
    p.add_argument("--dt", type=float, default=0.02, help="control period [s] (default 0.02)")
    p.add_argument("--line-rate", type=float, nargs="+", default=[0.0, 115200.0],
                   metavar="BAUD", help="emulated line rates, one run each (0: instantaneous; "
                                        "default: 0 115200)")
    p.add_argument("--transport", choices=["pty", "tcp"], default="pty",
                   help="the emulator's link (default pty)")
    p.add_argument("--in-process", action="store_true",
                   help="run the emulator in a thread of this process (default: a child process)")
    p.add_argument("--latency", type=float, default=0.0, metavar="MS",
                   help="injected reply latency [ms] (default 0)")
    p.add_argument("--garble", type=float, default=0.0, metavar="P",
                   help="injected garbling probability (default 0)")
    p.add_argument("--seed", type=seed, default=0,
                   help="random seed of the injected faults (default 0)")
    p.add_argument("--url", help="measure a real board at this pyserial URL instead "
                                 "(it will MOVE: legs within 10 mm of mid-stroke; default: "
                                 "the emulator)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark and print the table; returns the exit status."""
    p = build_parser()
    args = p.parse_args(argv)
    check_counts(p, args, "--periods")
    if not (math.isfinite(args.dt) and args.dt > 0):
        p.error(f"--dt: a positive control period in seconds, got {args.dt}")
    for rate in args.line_rate:
        if not rate >= 0:
            p.error(f"--line-rate: non-negative rates in baud, got {rate}")
    if not (math.isfinite(args.latency) and args.latency >= 0):
        p.error(f"--latency: a reply latency in milliseconds >= 0, got {args.latency}")
    if not 0 <= args.garble <= 1:
        p.error(f"--garble: a probability in [0, 1], got {args.garble}")
    rows = []
    print(f"# serial link: {args.periods} periods of {args.dt * 1e3:.0f} ms "
          f"({platform.processor() or platform.machine()}, Python "
          f"{platform.python_version()}, {sys.platform})", flush=True)
    if args.url:
        with SerialRobot(args.url) as robot:
            rows.append(measure(robot, f"{args.url} ({robot.identity})", args.periods, args.dt))
    else:
        faults = FaultConfig(latency=args.latency / 1e3, garble_rate=args.garble,
                             seed=args.seed)
        for rate in args.line_rate:
            where = "thread" if args.in_process else "process"
            label = (f"emulator {args.transport} ({where}), "
                     + (f"line {rate:.0f} baud" if rate else "instant line"))
            if args.latency:
                label += f", +{args.latency:g} ms"
            if args.garble:
                label += f", garble {args.garble:g}"
            with open_emulated_robot(deltalab(), faults=faults, line_rate=rate,
                                     transport=args.transport,
                                     process=not args.in_process) as robot:
                rows.append(measure(robot, label, args.periods, args.dt))
    print(format_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
