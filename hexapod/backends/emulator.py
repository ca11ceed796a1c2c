"""An emulator of the hexapod's controller board, on a pseudo-terminal or a loopback socket.

The emulator is split along its seams:

- :mod:`hexapod.backends.emulator_board`: the board (:class:`Board`, a state machine that
  speaks the serial protocol of :mod:`hexapod.backends.protocol`,
  ``docs/serial-protocol.md``), its configuration (:class:`BoardConfig`) and
  :class:`Emulator`, the board served on a pseudo-terminal or a loopback TCP port;
- :mod:`hexapod.backends.emulator_server`: the generic server (:class:`EmulatorServer`)
  that serves any line-oriented device, with seeded faults (:class:`FaultConfig`):
  latency, dropped replies, garbled bytes, a silent device, a disconnection;
- this module: :class:`EmulatorProcess` (the emulator in a child process) and the console
  script ``hexapod-emulator`` (:func:`main`), which prints the device path (or socket URL)
  as its first line on stdout, then serves until Ctrl-C. The public names of the other
  two modules are re-exported here, so ``from hexapod.backends.emulator import Emulator``
  keeps working.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import select
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from types import FrameType, TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np

from hexapod.backends import protocol
from hexapod.backends.emulator_board import ARRIVED, STROKE_TOL, Board, BoardConfig, Emulator
from hexapod.backends.emulator_server import (
    DISCONNECT_GRACE,
    EmulatedDevice,
    EmulatorServer,
    FaultConfig,
)
from hexapod.exceptions import BackendError
from hexapod.geometry import HexapodGeometry

if TYPE_CHECKING:
    from hexapod.backends.gcs_emulator import GcsConfig

logger = logging.getLogger(__name__)

__all__ = [
    "ARRIVED",
    "DISCONNECT_GRACE",
    "STROKE_TOL",
    "Board",
    "BoardConfig",
    "EmulatedDevice",
    "Emulator",
    "EmulatorProcess",
    "EmulatorServer",
    "FaultConfig",
    "main",
]


# ============================================================================ in a process
def config_to_args(config: BoardConfig, faults: FaultConfig | None = None) -> list[str]:
    """Command-line options of ``hexapod-emulator`` that describe a board and its faults."""
    c = config
    args = ["--stroke", protocol.format_mm(c.stroke[0]), protocol.format_mm(c.stroke[1]),
            "--speed", protocol.format_mm(c.max_speed), "--lag", repr(c.lag),
            "--watchdog", str(round(c.watchdog * 1e3)), "--identity", c.identity]
    if c.lengths is not None:
        args += ["--lengths", *(protocol.format_mm(x) for x in c.lengths)]
    if c.dynamics is not None:  # the robot file (or preset) whose mass and drives move it
        args += ["--dynamics", "--geometry", c.dynamics.source or c.dynamics.name,
                 "--physics-dt", repr(c.physics_dt * 1e3)]
    if faults is not None:
        args += faults.to_args()
    return args


class EmulatorProcess:
    """``hexapod-emulator`` in a child process (its own interpreter, so its timing does
    not share the host's GIL), started with ``python -m hexapod.backends.emulator``.

    Args:
        config: The board (default board if None).
        faults: Faults to inject.
        transport: ``"pty"`` or ``"tcp"`` (loopback, any free port).
        line_rate: Emulated line rate [baud] (0: instantaneous).
        startup_timeout: Longest wait for the device line [s].
        options: ``hexapod-emulator`` options that replace those of ``config`` and
            ``faults`` (e.g. ``["--gcs", "--geometry", "robot.toml"]``).

    Attributes:
        url: The device path or ``socket://`` URL printed by the emulator.
    """

    def __init__(self, config: BoardConfig | None = None, faults: FaultConfig | None = None,
                 *, transport: str = "pty", line_rate: float = 0.0,
                 startup_timeout: float = 30.0, options: Sequence[str] | None = None) -> None:
        where = ["--pty"] if transport == "pty" else ["--tcp", "127.0.0.1:0"]
        described = (list(options) if options is not None
                     else config_to_args(config or BoardConfig(), faults))
        args = [sys.executable, "-m", "hexapod.backends.emulator", *where, *described,
                "--line-rate", repr(line_rate)]
        # its own process group: a Ctrl-C at the terminal reaches the host, which halts
        # the robot through it, and not the emulator (it died first, the halt unconfirmed);
        # it ends with the host all the same (CHILD_OF below)
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, process_group=0,
                                     env={**os.environ, CHILD_OF: str(os.getpid())})
        if self.proc.stdout is None:
            raise BackendError("hexapod-emulator: no stdout")
        ready, _, _ = select.select([self.proc.stdout], [], [], startup_timeout)
        line = self.proc.stdout.readline().strip() if ready else ""
        if not line:
            self.stop()
            err = self.proc.stderr.read() if self.proc.stderr is not None else ""
            raise BackendError(f"hexapod-emulator did not start: {err.strip()[-500:]}")
        self.url = line
        self.device = line

    @property
    def running(self) -> bool:
        """The process is alive."""
        return self.proc.poll() is None

    def stop(self, timeout: float = 5.0) -> int | None:
        """Terminate the process (SIGTERM, then SIGKILL) and return its exit status."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()
        return self.proc.returncode

    def __enter__(self) -> EmulatorProcess:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


# ============================================================================ command line
def _parse_tcp(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or int(port) > 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT (a port of 0 to 65535), got "
                                         f"'{text}'")
    return host.strip("[]") or "127.0.0.1", int(port)


def _load_geometry(name: str) -> HexapodGeometry:
    from hexapod.geometry import preset

    if name.endswith(".toml") or Path(name).is_file():
        return HexapodGeometry.from_toml(name)
    return preset(name)


def build_parser() -> argparse.ArgumentParser:
    """The ``hexapod-emulator`` argument parser."""
    p = argparse.ArgumentParser(
        prog="hexapod-emulator",
        description="Emulate the hexapod's controller board (docs/serial-protocol.md), or "
                    "with --gcs a PI GCS hexapod controller (docs/backends.md), on a "
                    "pseudo-terminal or a loopback TCP port. Prints the device path (or "
                    "URL) as the first line on stdout, then serves until Ctrl-C.",
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="serve on a new pseudo-terminal")
    where.add_argument("--tcp", type=_parse_tcp, metavar="HOST:PORT",
                       help="serve on a TCP port (loopback only; port 0: any free port)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a non-loopback --tcp address (the robot then obeys the network)")
    robot = p.add_argument_group("robot")
    robot.add_argument("--geometry", default="deltalab",
                       help="geometry preset name or TOML file (stroke and speed; "
                            "default: deltalab)")
    robot.add_argument("--stroke", type=float, nargs=2, metavar=("MIN", "MAX"),
                       help="stroke limits [mm] (default: from the geometry)")
    robot.add_argument("--speed", type=float, metavar="MM_S",
                       help="leg speed limit [mm/s] (default: from the geometry)")
    robot.add_argument("--lengths", type=float, nargs="+", metavar="MM",
                       help="initial leg lengths [mm]: one for all legs or six "
                            "(default: mid-stroke)")
    robot.add_argument("--lag", type=float, metavar="S",
                       help="first-order lag time constant of each leg [s] (default 0; "
                            "not with --gcs)")
    robot.add_argument("--dynamics", action="store_true",
                       help="the axes move as the robot with mass and drives (the geometry's "
                            "[inertia] and [drives], velocity mode under a position loop: "
                            "lag, force limit, friction, gravity)")
    robot.add_argument("--physics-dt", type=float, default=1.0, metavar="MS",
                       help="physics step of --dynamics [ms] (default 1)")
    robot.add_argument("--identity", help="the *IDN? text (default: emulator and geometry name)")
    robot.add_argument("--watchdog", type=int, metavar="MS",
                       help=f"initial watchdog period [ms] (default "
                            f"{protocol.WATCHDOG_DEFAULT_MS}; not with --gcs)")
    gcs = p.add_argument_group("PI GCS hexapod controller (--gcs)")
    gcs.add_argument("--gcs", action="store_true",
                     help="emulate a GCS hexapod controller (C-887 family): MOV/POS?/VMO?/"
                          "VLS/HLT/STP/ERR?/SPI/ONT?/*IDN? in X Y Z [mm] U V W [deg]; the "
                          "geometry is the TRUE robot; prints tcp://HOST:PORT or "
                          "serial:/dev/pts/N")
    gcs.add_argument("--pose", type=float, nargs=6, metavar=("X", "Y", "Z", "U", "V", "W"),
                     help="initial pose [mm, deg] (default: the zero position, or --lengths)")
    gcs.add_argument("--zero-height", type=float, metavar="MM",
                     help="height of the platform frame at the zero position [mm] "
                          "(default: the geometry's home height)")
    gcs.add_argument("--pivot", type=float, nargs=3, metavar=("R", "S", "T"),
                     default=(0.0, 0.0, 0.0), help="pivot point in the platform frame [mm]")
    gcs.add_argument("--velocity", type=float, default=10.0, metavar="MM_S",
                     help="initial system velocity VLS [mm/s and deg/s] (default 10)")
    gcs.add_argument("--max-velocity", type=float, default=500.0, metavar="MM_S",
                     help="largest VLS accepted [mm/s and deg/s] (default 500)")
    gcs.add_argument("--rotation-order", default="moving-xyz",
                     choices=["moving-xyz", "fixed-xyz"],
                     help="U, V, W: Rx(U) Ry(V) Rz(W) about moving axes (default) or "
                          "Rz(W) Ry(V) Rx(U) about fixed axes")
    faults = p.add_argument_group("fault injection (seeded)")
    faults.add_argument("--latency", type=float, default=0.0, metavar="MS",
                        help="delay added to every reply [ms]")
    faults.add_argument("--jitter", type=float, default=0.0, metavar="MS",
                        help="extra uniform delay in [0, JITTER] per reply [ms]")
    faults.add_argument("--drop", type=float, default=0.0, metavar="P",
                        help="probability of dropping a reply")
    faults.add_argument("--garble", type=float, default=0.0, metavar="P",
                        help="probability of corrupting one byte of a command or a reply")
    faults.add_argument("--silent-after", type=int, metavar="N",
                        help="stop replying after N commands (still executing them)")
    faults.add_argument("--disconnect-after", type=int, metavar="N",
                        help="close the connection after replying to N commands")
    faults.add_argument("--stall-after", type=int, metavar="N",
                        help="after N commands, stall for --stall-ms: nothing read, executed "
                             "or answered, then every waiting command executed in order")
    faults.add_argument("--stall-ms", type=float, default=2000.0, metavar="MS",
                        help="duration of the --stall-after stall [ms] (default 2000)")
    faults.add_argument("--glitch-after", type=int, metavar="N",
                        help="after N commands, report the first leg --glitch-mm longer than "
                             "it is (a glitching encoder; with --gcs: the platform --glitch-mm "
                             "further along X)")
    faults.add_argument("--glitch-mm", type=float, default=30.0, metavar="MM",
                        help="the --glitch-after offset [mm] (default 30)")
    faults.add_argument("--drive-fault-after", type=int, metavar="N",
                        help="at command N, latch a drive fault of --drive-fault-code (the "
                             "legs hold; every MOV is answered with it; ERR? reads and clears "
                             "it; serial board)")
    faults.add_argument("--drive-fault-code", type=int, default=30, metavar="CODE",
                        help="the --drive-fault-after code (default 30, not a protocol code)")
    faults.add_argument("--seed", type=int, default=0, help="seed of the faults (default 0)")
    p.add_argument("--line-rate", type=float, default=0.0, metavar="BAUD",
                   help="emulate the transmission time of the lines at this baud rate "
                        "(e.g. 115200; default 0: instantaneous)")
    p.add_argument("--log-level", default="WARNING",
                   choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="logging level (stderr)")
    return p


def _faults_from_args(args: argparse.Namespace) -> FaultConfig:
    return FaultConfig(latency=args.latency / 1e3, jitter=args.jitter / 1e3,
                       drop_rate=args.drop, garble_rate=args.garble,
                       silent_after=args.silent_after, disconnect_after=args.disconnect_after,
                       stall_after=args.stall_after, stall_s=args.stall_ms / 1e3,
                       glitch_after=args.glitch_after, glitch=args.glitch_mm / 1e3,
                       drive_fault_after=args.drive_fault_after,
                       drive_fault_code=args.drive_fault_code, seed=args.seed)


def _robot_from_args(args: argparse.Namespace
                     ) -> tuple[HexapodGeometry, tuple[float, ...] | None]:
    geometry = _load_geometry(args.geometry)
    if args.stroke is not None:  # checked in the options' units (mm) first
        lo, hi = args.stroke
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise BackendError(f"--stroke {lo:g} {hi:g}: expected 0 < MIN < MAX [mm]")
        geometry = geometry.replace(stroke=(lo / 1e3, hi / 1e3))
    if args.speed is not None:
        if not (math.isfinite(args.speed) and args.speed > 0):
            raise BackendError(f"--speed {args.speed:g}: must be positive and finite [mm/s]")
        geometry = geometry.replace(max_speed=args.speed / 1e3)
    lengths = None
    if args.lengths is not None:
        if len(args.lengths) not in (1, 6):
            raise BackendError(f"--lengths takes 1 or 6 values, got {len(args.lengths)}")
        lengths = tuple(np.broadcast_to(np.array(args.lengths) / 1e3, (6,)).tolist())
    return geometry, lengths


def config_from_args(args: argparse.Namespace) -> tuple[BoardConfig, FaultConfig]:
    """The board and faults described by parsed command-line arguments."""
    geometry, lengths = _robot_from_args(args)
    if args.dynamics and args.lag:  # (accepted, and without effect: the drives move it)
        raise BackendError("--lag is the legs' first-order lag of the board without "
                           "dynamics; with --dynamics the robot file's [drives] move the "
                           "legs: drop --lag, or set its drives' velocity_bandwidth")
    watchdog = protocol.WATCHDOG_DEFAULT_MS if args.watchdog is None else args.watchdog
    board = BoardConfig(stroke=geometry.stroke, max_speed=geometry.max_speed, lengths=lengths,
                        lag=0.0 if args.lag is None else args.lag, watchdog=watchdog / 1e3,
                        identity=args.identity or f"hexapod-emulator 0.1.0 {geometry.name}",
                        dynamics=geometry if args.dynamics else None,
                        physics_dt=args.physics_dt / 1e3)
    return board, _faults_from_args(args)


def gcs_config_from_args(args: argparse.Namespace) -> tuple[GcsConfig, FaultConfig]:
    """The GCS hexapod (``--gcs``) and faults described by parsed command-line arguments."""
    from hexapod.backends.gcs_emulator import GcsConfig

    for name in ("lag", "watchdog", "drive_fault_after"):  # (the last was ignored)
        if getattr(args, name, None) is not None:
            raise BackendError(f"--{name.replace('_', '-')} is an option of the serial "
                               "board, not of --gcs")
    if args.pose is not None and args.lengths is not None:
        raise BackendError("--pose and --lengths both give the initial pose: choose one")
    geometry, lengths = _robot_from_args(args)
    coords = None
    if args.pose is not None:
        p = np.asarray(args.pose, float)
        coords = (*(p[:3] * 1e-3).tolist(), *np.deg2rad(p[3:]).tolist())
    extra = {"identity": args.identity} if args.identity else {}
    config = GcsConfig(geometry, lengths=lengths, coords=coords,
                       pivot=tuple(np.asarray(args.pivot, float) * 1e-3),
                       rotation_order=args.rotation_order, velocity=args.velocity / 1e3,
                       zero_height=None if args.zero_height is None else args.zero_height / 1e3,
                       max_velocity=args.max_velocity / 1e3, dynamics=args.dynamics,
                       physics_dt=args.physics_dt / 1e3, **extra)
    return config, _faults_from_args(args)


#: Set by :class:`EmulatorProcess` to the host's process id: the emulator then ends with
#: the host however the host ends (Linux), being out of its process group.
CHILD_OF = "HEXAPOD_EMULATOR_CHILD_OF"


def _end_with_parent() -> None:
    """Ask Linux for SIGTERM when the host that started this emulator ends."""
    from hexapod.parent import end_with_parent

    parent = os.environ.pop(CHILD_OF, None)
    if parent is not None and parent.isdigit():
        end_with_parent(int(parent))


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``hexapod-emulator``: serve a board (or, with ``--gcs``, a GCS hexapod
    controller) until Ctrl-C or SIGTERM.

    Returns:
        The exit status (0 on a normal stop, 2 on a bad option).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    _end_with_parent()
    logging.basicConfig(level=args.log_level, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    transport = "pty" if args.tcp is None else "tcp"
    host, port = ("127.0.0.1", 0) if args.tcp is None else args.tcp
    emu: EmulatorServer[Any]
    try:
        if args.gcs:
            from hexapod.backends.gcs_emulator import GcsEmulator

            gcs, faults = gcs_config_from_args(args)
            emu = GcsEmulator(gcs, faults, transport=transport, host=host, port=port,
                              allow_remote=args.allow_remote, line_rate=args.line_rate)
        else:
            board, faults = config_from_args(args)
            emu = Emulator(board, faults, transport=transport, host=host, port=port,
                           allow_remote=args.allow_remote, line_rate=args.line_rate)
        emu.open()
    except (BackendError, OSError, ValueError) as exc:
        print(f"hexapod-emulator: error: {exc}", file=sys.stderr)
        return 2

    def _terminate(signum: int, frame: FrameType | None) -> None:
        emu.request_stop()

    signal.signal(signal.SIGTERM, _terminate)
    print(emu.url, flush=True)
    try:
        emu.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        emu.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
