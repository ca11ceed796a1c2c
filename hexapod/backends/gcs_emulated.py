"""An emulated GCS hexapod with a :class:`~hexapod.backends.gcs.GcsHexapod` connected to it:
the ``gcs-emulator`` backend (:func:`open_from_spec`) and :func:`open_emulated_gcs`."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.backends.base import started
from hexapod.backends.emulator_server import FaultConfig
from hexapod.backends.gcs_emulator import GcsConfig, GcsEmulator
from hexapod.exceptions import BackendError
from hexapod.geometry import HexapodGeometry

__all__ = ["gcs_config_to_args", "open_emulated_gcs", "open_from_spec"]


def gcs_config_to_args(config: GcsConfig, geometry_file: str,
                       faults: FaultConfig | None = None) -> list[str]:
    """``hexapod-emulator --gcs`` options that describe a hexapod (its geometry saved in
    ``geometry_file``) and its faults."""
    c = config
    args = ["--gcs", "--geometry", geometry_file,
            "--pivot", *(repr(x * 1e3) for x in c.pivot),
            "--rotation-order", c.rotation_order, "--velocity", repr(c.velocity * 1e3),
            "--max-velocity", repr(c.max_velocity * 1e3), "--identity", c.identity]
    if c.zero_height is not None:
        args += ["--zero-height", repr(c.zero_height * 1e3)]
    if c.lengths is not None:
        args += ["--lengths", *(repr(x * 1e3) for x in c.lengths)]
    if c.coords is not None:
        p = np.asarray(c.coords)
        args += ["--pose", *(repr(x) for x in (*(p[:3] * 1e3), *np.rad2deg(p[3:])))]
    if faults is not None:
        args += faults.to_args()
    return args


def open_emulated_gcs(geometry: HexapodGeometry, lengths: np.ndarray | None = None, *,
                      nominal: HexapodGeometry | None = None,
                      faults: FaultConfig | None = None, process: bool = False,
                      transport: str = "tcp", options: Any = None,
                      **config_changes: Any) -> Any:
    """Start an emulated GCS hexapod and connect a :class:`~hexapod.backends.gcs.GcsHexapod`.

    Closing the robot stops the emulator.

    Args:
        geometry: The emulator's TRUE robot.
        lengths: Its initial leg lengths [m] (the zero position if None).
        nominal: The robot the backend believes in (``geometry`` if None). The
            emulator's zero position is then the nominal home pose (unless
            ``zero_height`` is given), so that both agree on the origin of the coordinates
            as a client and its controller do once installed (``zero_mm``).
        faults: Faults the emulator injects.
        process: Run the emulator in a child process (``hexapod-emulator --gcs``) instead
            of a thread of this interpreter.
        transport: ``"tcp"`` (loopback) or ``"pty"``.
        options: :class:`~hexapod.backends.gcs_config.GcsOptions` of the backend.
        config_changes: Other :class:`GcsConfig` fields (``pivot``, ``rotation_order``...).

    Returns:
        The connected robot; ``robot.emulator`` is the running :class:`GcsEmulator` (or
        :class:`~hexapod.backends.emulator.EmulatorProcess`).
    """
    from hexapod.backends.emulator import EmulatorProcess
    from hexapod.backends.gcs import GcsHexapod

    q = None if lengths is None else tuple(np.asarray(lengths, dtype=float).tolist())
    if nominal is not None:
        config_changes.setdefault("zero_height", nominal.home_height)
    config = GcsConfig(geometry, lengths=q, **config_changes)
    emu: GcsEmulator | EmulatorProcess
    if process:
        with tempfile.TemporaryDirectory(prefix="hexapod-gcs-") as tmp:
            path = str(Path(tmp) / "true-robot.toml")
            geometry.to_toml(path)
            emu = EmulatorProcess(transport=transport,
                                  options=gcs_config_to_args(config, path, faults))
    else:
        emu = GcsEmulator(config, faults, transport=transport).start()

    def stop_emulator() -> None:
        emu.stop()

    try:
        robot = GcsHexapod(emu.url, nominal or geometry, options, on_close=stop_emulator)
    except BaseException:
        emu.stop()
        raise
    robot.emulator = emu
    return robot


#: ``gcs-emulator:KEY=VALUE,...`` keys: faults of the emulator.
_FAULT_KEYS: dict[str, tuple[str, Callable[[str], Any]]] = {
    "latency_ms": ("latency", lambda s: float(s) * 1e-3),
    "jitter_ms": ("jitter", lambda s: float(s) * 1e-3),
    "drop": ("drop_rate", float),
    "garble": ("garble_rate", float),
    "silent_after": ("silent_after", int),
    "disconnect_after": ("disconnect_after", int),
    "seed": ("seed", int),
}


def open_from_spec(args: str, geometry: HexapodGeometry, start: np.ndarray | None) -> Any:
    """The ``gcs-emulator[:KEY=VALUE,...]`` backend: an emulator per call whose TRUE robot
    is ``geometry`` at ``start``, and a backend connected to it on loopback TCP.

    Keys: the emulator's faults (``latency_ms``, ``jitter_ms``, ``drop``, ``garble``,
    ``silent_after``, ``disconnect_after``, ``seed``), ``process=1`` (a child process),
    and the backend's options (``vmo``, ``vmo_margin_mm``, ``timeout``, ``velocity``...,
    :class:`~hexapod.backends.gcs_config.GcsOptions`).

    Raises:
        BackendError: An unknown key or a bad value.
    """
    faults, process, options = parse_spec(args)
    robot = open_emulated_gcs(geometry, start, faults=faults, process=process,
                              options=options)
    return started(robot, start)


def parse_spec(args: str) -> tuple[FaultConfig | None, bool, Any]:
    """The faults, whether in a child process, and the backend's options of a
    ``gcs-emulator`` spec's arguments (:func:`open_from_spec`; checked before anything is
    opened).

    Raises:
        BackendError: An unknown key or a bad value.
    """
    from hexapod.backends.gcs_config import GcsOptions

    faults: dict[str, Any] = {}
    backend_items: list[str] = []
    process = False
    for item in filter(None, args.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise BackendError(f"gcs-emulator option {item!r}: expected KEY=VALUE")
        try:
            if key in _FAULT_KEYS:
                name, convert = _FAULT_KEYS[key]
                faults[name] = convert(value)
            elif key == "process":
                process = value not in ("0", "false", "no")
            else:
                backend_items.append(item)
        except ValueError as exc:
            raise BackendError(f"gcs-emulator option {item!r}: {exc}") from None
    from hexapod.backends.gcs_config import option_keys

    for item in backend_items:  # (an unknown key was named with the backend's keys only)
        if item.partition("=")[0] not in option_keys():
            keys = sorted([*_FAULT_KEYS, "process", *option_keys()])
            raise BackendError(f"gcs-emulator option {item!r}: expected KEY=VALUE with KEY "
                               f"one of {', '.join(keys)}")
    _, options = GcsOptions.parse("?" + "&".join(backend_items))
    return FaultConfig(**faults) if faults else None, process, options
