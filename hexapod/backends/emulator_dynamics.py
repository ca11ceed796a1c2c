"""The emulated boards' axes as the dynamic robot (``hexapod-emulator --dynamics``).

Without it an emulated leg moves at the speed limit straight to its setpoint. With it,
each axis is what a real controller drives: a **position loop** (proportional, bandwidth
:data:`POSITION_BANDWIDTH_HZ`, its output limited to the board's speed) whose velocity
is the setpoint of the leg's **velocity-mode drive** on the TRUE robot with mass
(:class:`hexapod.dynamics.robots.DynamicRobots`: the robot file's ``[inertia]`` and
``[drives]``, integrated at ``physics_dt``). So a servo loop talking to the emulator meets
the drives' lag, their force limit and friction, and gravity.

The state advances lazily: when the board is asked (a command, the watchdog), the axes
are integrated over the time elapsed since, in whole physics steps (the remainder is
carried to the next call), with the setpoints held meanwhile, as they were.

An idle emulator costs nothing: the robot starts at rest, and comes to rest again once
it has held the same setpoints for :data:`REST_AFTER` seconds with every leg slower than
:data:`REST_SPEED` and within :data:`REST_ERROR` of its setpoint (the drives' integral
action has then nothing left to do but sub-micrometre creep); at rest the physics steps
are skipped until the setpoints change.
"""

from __future__ import annotations

import logging

import numpy as np

from hexapod.dynamics.robots import DynamicRobots
from hexapod.exceptions import BackendError, HexapodError
from hexapod.fk import forward_kinematics
from hexapod.geometry import HexapodGeometry

log = logging.getLogger(__name__)

#: Bandwidth of the axes' position loop [Hz] (a fifth of the drives' default 50 Hz).
POSITION_BANDWIDTH_HZ = 10.0
#: Longest catch-up integrated at once [s]; a longer silence jumps (the robot is at
#: rest under its position loop long before).
MAX_CATCH_UP = 5.0
#: At rest: every leg slower than this [m/s] ...
REST_SPEED = 1e-6
#: ... and within this of its position setpoint [m] ...
REST_ERROR = 5e-7
#: ... for this long, the setpoints unchanged [s].
REST_AFTER = 0.5


class DynamicAxes:
    """Six axes of one robot with mass and drives.

    Args:
        geometry: The TRUE robot (kinematics, inertia, drives in velocity mode).
        lengths: Initial leg lengths (6,) [m] (the robot starts at rest there).
        physics_dt: Physics step [s].

    Raises:
        BackendError: The drives are in force mode, or the lengths have no pose.
    """

    def __init__(self, geometry: HexapodGeometry, lengths: np.ndarray,
                 physics_dt: float = 1e-3) -> None:
        if geometry.drives.mode != "velocity":
            raise BackendError("--dynamics needs drives in velocity mode (a board sends "
                               f"position setpoints), the robot file has {geometry.drives.mode!r}")
        if not (np.isfinite(physics_dt) and 0 < physics_dt <= 0.01):
            raise BackendError(f"--physics-dt must be in (0, 10] ms, got {physics_dt * 1e3:g} "
                               "ms")
        try:
            fk = forward_kinematics(geometry, np.asarray(lengths, float))
        except HexapodError as exc:
            raise BackendError(f"initial lengths {np.round(np.asarray(lengths) * 1e3, 3)} mm "
                               f"have no pose: {exc}") from None
        self.robots = DynamicRobots([geometry], fk.rotation[None].copy(),
                                    fk.translation[None].copy())
        self.h = physics_dt
        self.gain = 2 * np.pi * POSITION_BANDWIDTH_HZ
        self._carry = 0.0
        self._rows = np.array([0])
        self.lengths = self.robots.lengths(self._rows)[0]
        self._resting = True
        self._rest = np.array(lengths, dtype=float)
        self._still_for = 0.0
        self._warm_up()

    def _warm_up(self) -> None:
        """Build (or load from the disk cache) the compiled code of a physics step now:
        a first compilation takes seconds, and a server must not stall its first command
        on it."""
        from hexapod.dynamics.robots_compiled import period_function, period_lanes

        if period_lanes() is None:
            period_function(1)
        self.leg_velocities()

    def leg_velocities(self) -> np.ndarray:
        """The legs' velocities now (6,) [m/s]."""
        r = self.robots
        _, _, K, _, _ = r.model.terms_batch(r.R, r.t, r.twist, **r.rows(self._rows))
        return K[0] @ r.twist[0]  # type: ignore[no-any-return]

    def steps_for(self, dt: float) -> int:
        """The whole physics steps in ``dt`` [s] plus the remainder carried so far (the
        new remainder is carried on)."""
        elapsed = min(dt, MAX_CATCH_UP) + self._carry
        steps = int(elapsed / self.h)
        self._carry = elapsed - steps * self.h
        return steps

    def step(self, setpoints: np.ndarray, speed: float) -> None:
        """One physics step towards the position setpoints (6,) [m], the position loop's
        velocity limited to ``speed`` [m/s]. Until the first setpoint away from where it
        started, the robot is at rest in equilibrium (drives holding gravity) and the
        step is skipped (it would move it by round-off only): an idle emulator costs
        nothing."""
        if self._resting:
            if np.array_equal(setpoints, self._rest):
                return
            self._resting = False
        v = np.clip(self.gain * (setpoints - self.lengths), -speed, speed)
        if self.robots.advance(self._rows, v[None], self.h, 1).any():
            raise BackendError("the dynamic robot diverged (a non-finite state)")
        self.lengths = self.robots.lengths(self._rows)[0]

    def move(self, setpoints: np.ndarray, speed: float, dt: float) -> np.ndarray:
        """Integrate ``dt`` [s] with the position setpoints (6,) [m] held, the position
        loop's velocity limited to ``speed`` [m/s]; returns the leg lengths (6,) [m].
        Once the robot has come to rest at these setpoints (module docstring), nothing
        is integrated until they change."""
        return self.hold(setpoints, speed, self.steps_for(dt))

    def hold(self, setpoints: np.ndarray, speed: float, steps: int) -> np.ndarray:
        """``steps`` physics steps with the position setpoints (6,) [m] held (:meth:`move`
        for a number of steps); returns the leg lengths (6,) [m]."""
        if self._resting and np.array_equal(setpoints, self._rest):
            return self.lengths.copy()
        if steps:
            self.step(setpoints, speed)  # the whole path once: the table holds the period
            if steps > 1:
                self._steps(setpoints, speed, steps - 1)
            self._watch_rest(setpoints, steps * self.h)
        return self.lengths.copy()

    def _steps(self, setpoints: np.ndarray, speed: float, steps: int) -> None:
        """``steps`` more physics steps of :meth:`step`, the same operations on the same
        numbers (the same bits), without its per-call bookkeeping: the robot's row stays
        in the compiled period's table, only the position loop's velocity is written
        into it each step, and the pose goes back to the robot at the end (a physics step
        costs 1.4 us in C; :meth:`step`'s conversions around it 75 us, which on a loaded
        machine kept the emulator from answering in time)."""
        from hexapod.dynamics.robots_compiled import LAYOUT, period_lanes

        lanes = period_lanes()
        if lanes is None:  # no compiled lanes: the general path
            for _ in range(steps):
                self.step(setpoints, speed)
            return
        r, rows = self.robots, self._rows
        table = r.table
        cols_v, cols_R, cols_t = LAYOUT["setpoint"], LAYOUT["R"], LAYOUT["t"]
        check = cols_v.start  # the state: pose, twist, integral
        A, E = r.A[rows], r.E[rows]
        for _ in range(steps):
            table[0, cols_v] = np.clip(self.gain * (setpoints - self.lengths), -speed, speed)
            if lanes.advance(table, rows, 1, check).any():
                raise BackendError("the dynamic robot diverged (a non-finite state)")
            R = np.swapaxes(table[0:1, cols_R].reshape(-1, 3, 3), -1, -2)
            leg = table[0:1, cols_t][:, None, :] + np.einsum("nij,nkj->nki", R, E) - A
            self.lengths = np.linalg.norm(leg, axis=-1)[0]  # hexapod.dynamics.robots.legs
            r.R[0] = R[0]
        r.t[0] = table[0, cols_t]
        if r.drives.mode == "velocity":
            r.track_count[0] += 6 * steps

    def _watch_rest(self, setpoints: np.ndarray, dt: float) -> None:
        """Count how long the robot has been still at ``setpoints``; at rest after
        :data:`REST_AFTER` seconds."""
        if not np.array_equal(setpoints, self._rest):
            self._rest = np.array(setpoints, dtype=float)
            self._still_for = 0.0
            return
        still = (float(np.max(np.abs(setpoints - self.lengths))) <= REST_ERROR
                 and bool(np.all(np.abs(self.leg_velocities()) <= REST_SPEED)))
        self._still_for = self._still_for + dt if still else 0.0
        if self._still_for >= REST_AFTER:
            self._resting = True
            log.debug("dynamic axes at rest at %s mm", np.round(self.lengths * 1e3, 4))

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The platform's true pose now: rotation (3, 3), position (3,) [m]."""
        return self.robots.R[0].copy(), self.robots.t[0].copy()

    @property
    def settled(self) -> bool:
        """Every leg slower than 1 um/s."""
        return bool(np.all(np.abs(self.leg_velocities()) <= 1e-6))
