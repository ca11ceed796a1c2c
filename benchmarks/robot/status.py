"""What a servo session shows and returns: one period's status (:class:`PeriodStatus`, a
line of the log), the session's result (:class:`ServoResult`) and the live status line
(:class:`StatusLine`: one rewritten line on a terminal, plain lines otherwise)."""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import IO, Any

import numpy as np

from benchmarks.robot.exits import SessionStop
from benchmarks.robot.records import mm_list

#: Plain status lines (stdout not a terminal) are printed every this many seconds.
PLAIN_STATUS_PERIOD_S = 1.0

@dataclass
class PeriodStatus:
    """One period of the loop (what the status line and the log show).

    Attributes:
        step: Period index (from 0).
        t: Loop time at the start of the period [s].
        lengths: (6,) lengths measured at the end of the period [m].
        leg_error: max |q - q*| at the end of the period [m].
        feature_error: Feature error of this period's image (NaN for a lost frame).
        controller_error: The controller's own error norm (NaN if not run).
        velocities: (6,) the controller's command [m/s] (zeros when refused).
        visible_edges: Edges found in this period's image.
        reason: Why the command is zero (refusal, lost frame), or None.
        lost_frame: The camera gave no image this period.
        rtt: Time spent communicating with the robot (the link time) [s].
        missed: This period was late.
        missed_total, lost_total, refused_total: The counts so far.
        applied: (6,) the velocities the robot applied [m/s] (after every clamp).
        clamped: (6,) legs whose command was clamped (speed cap, stroke, speed limit).
        camera_s, controller_s: Time in the camera and in the controller [s].
        lost_frames: Frames the camera lost this period (dropped by the device too).
    """

    step: int
    t: float
    lengths: np.ndarray
    leg_error: float
    feature_error: float
    controller_error: float
    velocities: np.ndarray
    visible_edges: int
    reason: str | None
    lost_frame: bool
    rtt: float
    missed: bool
    missed_total: int
    lost_total: int
    refused_total: int
    applied: np.ndarray = field(default_factory=lambda: np.zeros(6))
    clamped: np.ndarray = field(default_factory=lambda: np.zeros(6, dtype=bool))
    camera_s: float = 0.0
    controller_s: float = 0.0
    lost_frames: int = 0

    def to_json(self) -> dict[str, Any]:
        """A log line (lengths in mm, velocities in mm/s, times in ms; NaN as null)."""
        def num(x: float, scale: float = 1.0) -> float | None:
            return float(x) * scale if math.isfinite(x) else None

        return {"step": self.step, "t_s": round(self.t, 6),
                "lengths_mm": mm_list(self.lengths),
                "leg_error_mm": num(self.leg_error, 1e3),
                "feature_error": num(self.feature_error),
                "controller_error": num(self.controller_error),
                "commanded_mm_s": mm_list(self.velocities),
                "applied_mm_s": mm_list(self.applied),
                "clamped": [bool(x) for x in self.clamped],
                "visible_edges": self.visible_edges, "reason": self.reason,
                "lost_frame": self.lost_frame, "lost_frames": self.lost_frames,
                "camera_ms": round(self.camera_s * 1e3, 4),
                "controller_ms": round(self.controller_s * 1e3, 4),
                "compute_ms": round((self.camera_s + self.controller_s) * 1e3, 4),
                "link_ms": num(self.rtt, 1e3), "rtt_ms": num(self.rtt, 1e3),
                "missed": self.missed}

    def line(self) -> str:
        """The status line (mm and ms)."""
        fe = f"{self.feature_error:.2e}" if math.isfinite(self.feature_error) else "   --   "
        s = (f"step {self.step:6d} {self.t:7.2f} s | feature err {fe} | "
             f"max|q-q*| {self.leg_error * 1e3:7.3f} mm | edges {self.visible_edges:2d} | "
             f"RTT {self.rtt * 1e3:5.2f} ms | missed {self.missed_total} | "
             f"lost {self.lost_total}")
        if self.reason:
            s += f"  [{self.reason}]"
        return s


@dataclass
class ServoResult:
    """Outcome of :func:`~benchmarks.robot.loop.servo_loop`.

    Attributes:
        outcome: ``"converged"``, ``"max-steps"``, ``"interrupted"``, ``"camera ended"``
            or ``"stopped"`` (by the :class:`~benchmarks.robot.exits.SessionStop` ``stop``).
        steps: Periods run.
        wall_s: Wall time of the loop [s].
        rtts, compute: Link time, and camera and controller time, of each period [s].
        missed, lost_frames, refused: Late periods, lost frames, refused commands.
        last: The last period's status, if any.
        stop: The stop request that ended the session, if any.
    """

    outcome: str
    steps: int
    wall_s: float
    rtts: list[float] = field(default_factory=list)
    missed: int = 0
    lost_frames: int = 0
    refused: int = 0
    last: PeriodStatus | None = None
    compute: list[float] = field(default_factory=list)
    stop: SessionStop | None = None

    def summary(self) -> str:
        """One line for the user (mm, ms, Hz): ``converged after N periods ...`` or
        ``stopped after N periods ...``."""
        rt = np.array(self.rtts) * 1e3 if self.rtts else np.array([math.nan])
        ct = np.array(self.compute) * 1e3 if self.compute else np.array([math.nan])
        verdict = "converged" if self.outcome == "converged" else "stopped"
        rate_hz = self.steps / self.wall_s if self.wall_s > 0 else math.nan
        s = (f"{verdict} after {self.steps} periods ({self.wall_s:.2f} s, "
             f"{rate_hz:.1f} Hz): {self.missed} missed periods, {self.lost_frames} lost "
             f"frames, {self.refused} refused commands; compute median {np.median(ct):.2f} "
             f"ms, p99 {np.percentile(ct, 99):.2f} ms; RTT median {np.median(rt):.2f} ms, "
             f"p99 {np.percentile(rt, 99):.2f} ms")
        if self.last is not None:
            s += (f"; final max|q-q*| {self.last.leg_error * 1e3:.3f} mm, feature error "
                  f"{self.last.feature_error:.2e}")
        return s


class StatusLine:
    """The live status: one rewritten line on a terminal (rich), plain lines otherwise.

    Args:
        stream: Where to write (default stdout).
        period_s: Plain mode: at most one line every ``period_s`` [s] (the first
            period and the refusals' changes are always shown).
    """

    def __init__(self, stream: IO[str] | None = None,
                 period_s: float = PLAIN_STATUS_PERIOD_S) -> None:
        self.stream = sys.stdout if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.period_s = float(period_s)
        self._last_print = -math.inf
        self._last_reason: str | None = None
        self._live: Any = None
        if self.tty:
            from rich.console import Console
            from rich.live import Live
            from rich.text import Text

            self._text = Text
            self._live = Live(Text(""), console=Console(file=self.stream),
                              auto_refresh=False, transient=False)
        # started at the first period: before it, the terminal is plain (a question such
        # as --confirm's is asked on it, not through the live display)
        self._started = False

    def __call__(self, status: PeriodStatus) -> None:
        """Show one period."""
        now = time.perf_counter()
        if self._live is not None:
            if not self._started:
                self._live.start()
                self._started = True
            if now - self._last_print >= 0.05 or status.reason != self._last_reason:
                style = "yellow" if status.reason else ""
                self._live.update(self._line(status, style), refresh=True)
                self._last_print = now
        elif (now - self._last_print >= self.period_s or status.reason != self._last_reason):
            print(status.line(), file=self.stream, flush=True)
            self._last_print = now
        self._last_reason = status.reason

    def _line(self, status: PeriodStatus, style: str = "") -> Any:
        """One terminal line: cropped to the width, never wrapped."""
        return self._text(status.line(), style=style, no_wrap=True, overflow="ellipsis")

    def final(self, status: PeriodStatus | None) -> None:
        """Show the last period and release the terminal line."""
        if self._live is not None:
            if status is not None:
                self._live.update(self._line(status), refresh=True)
            if self._started:
                self._live.stop()
            self._live = None
        elif status is not None:
            print(status.line(), file=self.stream, flush=True)

    def message(self, text: str) -> None:
        """A line of its own."""
        if self._live is not None:
            self._live.console.print(text, markup=False, highlight=False)
        else:
            print(text, file=self.stream, flush=True)
