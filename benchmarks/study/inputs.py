"""A run directory keeps what defined the run: ``DIR/inputs/SCENARIO/`` holds the scenario
file as read (``source.toml``), a runnable copy with the command-line overrides applied and
its paths made local (``scenario.toml``: ``hexapod-bench run DIR/inputs/NAME/scenario.toml``
runs the same study), and every file the scenario names (robot, camera and the OpenCV
file a camera names, calibration). ``settings`` lists, for ``run.json`` and the report,
the robot, camera, noise, calibration error, calibration and task of the run.
"""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import asdict
from pathlib import Path
from typing import Any

import tomli_w

from benchmarks.study.outdir import INPUTS_DIR
from hexapod.config import load_toml
from hexapod.outputs import TEXT_MARKER, inside


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _copy(src: str | Path, folder: Path, used: dict[str, str], role: str) -> str:
    """Copy ``src`` into ``folder`` under its name (prefixed with ``role`` on a clash)."""
    src = Path(src)
    name = src.name
    if name in used and used[name] != str(src.resolve()):
        name = f"{role}-{name}"
    used[name] = str(src.resolve())
    shutil.copyfile(src, inside(folder, name))
    return name


def _camera_copy(src: Path, folder: Path, used: dict[str, str]) -> str:
    """Copy a camera file; a camera TOML naming an OpenCV file gets it beside it."""
    if src.suffix != ".toml":
        return _copy(src, folder, used, "camera")
    table = load_toml(src)
    ref = table.get("opencv")
    if not isinstance(ref, str):
        return _copy(src, folder, used, "camera")
    ref_path = Path(ref) if Path(ref).is_absolute() else src.parent / ref
    table["opencv"] = _copy(ref_path, folder, used, "opencv")
    name = src.name if src.name not in used else f"camera-{src.name}"
    used[name] = str(src.resolve())
    inside(folder, name).write_text(tomli_w.dumps(table))
    return name


def copy_inputs(out: Path, sc: Any, allow_foreign: bool = False, keep: bool = True
                ) -> dict[str, Any]:
    """Copy a scenario and the files it names into ``out/inputs/NAME/``.

    Args:
        out: The run directory.
        sc: The scenario as run (command-line overrides applied).
        allow_foreign: ``--allow-foreign-calibration`` was given.
        keep: The directory's run is continued (resumed or grown): a copy it kept stays.
            False: a new run, whose copies replace whatever the folder holds (a
            directory the user gave with ``--overwrite``).

    Returns:
        What ``run.json`` records: the folder, the files with their SHA-256, and
        ``changed`` (a resumed run whose scenario file differs from the kept one: the
        kept copy stays, the caller warns).
    """
    folder = inside(out, INPUTS_DIR, sc.name)
    rel = f"{INPUTS_DIR}/{sc.name}"
    if sc.source == "<dict>" or not Path(sc.source).is_file():
        return {"folder": None, "note": "scenario built in code: no file to keep"}
    source = Path(sc.source)
    if keep and (folder / "source.toml").is_file():
        same = (folder / "source.toml").read_bytes() == source.read_bytes()
        _grow(folder / "scenario.toml", sc.trials)
        return {"folder": rel, "changed": not same, **_listing(folder)}
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source, folder / "source.toml")
    table = load_toml(source)
    used: dict[str, str] = {"source.toml": "", "scenario.toml": ""}
    if sc.robot_geometry:
        table.setdefault("robot", {})["geometry"] = _copy(sc.robot_geometry, folder, used,
                                                          "robot")
    if sc.robot_model:  # the controllers' model (an identified robot file)
        table.setdefault("robot", {})["model"] = _copy(sc.robot_model, folder, used, "model")
    if sc.camera_file:
        key = "opencv" if "opencv" in table.get("camera", {}) else "file"
        table.setdefault("camera", {})[key] = _camera_copy(Path(sc.camera_file), folder, used)
    cal = table.setdefault("calibration", {})
    if sc.calibration.method == "file" and sc.calibration.file:
        cal.update(method="file", file=_copy(sc.calibration.file, folder, used, "calibration"))
        if allow_foreign or sc.calibration.allow_foreign:
            cal["allow_foreign"] = True
    if not cal:
        del table["calibration"]
    table["trials"], table["seed"] = sc.trials, sc.seed
    table.setdefault("robot", {})["world"] = sc.world  # --world too
    table.setdefault("task", {})["max_steps"] = sc.task.max_steps
    if "task.goal" not in sc.sweep_axes:  # --goal too; a swept setting stays the file's list
        table["task"]["goal"] = sc.task.goal
    table["controllers"] = [{"name": c.name, "label": c.label, **c.options}
                            for c in sc.controllers]
    # each controller carries the [controller_options] it took (the pre-flight gave them
    # to the controllers that declare them): the table would give them again
    table.pop("controller_options", None)
    (folder / "scenario.toml").write_text(_HEADER + tomli_w.dumps(table))
    return {"folder": rel, "changed": False, **_listing(folder)}


#: The first lines of ``inputs/NAME/scenario.toml``.
_HEADER = (f"# {TEXT_MARKER}: the scenario of this run, command-line overrides applied "
           "and paths local (source.toml: the file as read)\n")


def _grow(path: Path, trials: int) -> None:
    """A grown study (more trials, everything else checked the same): the runnable copy
    says the new trial count."""
    if not path.is_file():
        return
    table = load_toml(path)
    if table.get("trials") != trials:
        table["trials"] = trials
        path.write_text(_HEADER + tomli_w.dumps(table))


def _listing(folder: Path) -> dict[str, Any]:
    return {"files": {p.name: _sha256(p) for p in sorted(folder.iterdir()) if p.is_file()}}


def _nonzero(values: dict[str, Any]) -> str:
    return ", ".join(f"{k} {v:g}" for k, v in values.items()) or "none"


def settings(sc: Any) -> dict[str, str]:
    """The settings that define a scenario's run, in words (``run.json``, the report).

    Swept keys show their values (``noise.amplitude_deg [0.01, 0.05]``).
    """
    from benchmarks.sim.goal import GOAL_TEXT
    from benchmarks.study.provenance import scenario_setup

    robot, g, cam_name, cam = scenario_setup(sc)
    lo, hi = (1e3 * x for x in g.stroke)
    n = sc.noise
    keys = {"none": (), "rotation": ("amplitude_deg",),
            "pixel": ("pixel_sigma_px", "points_per_edge", "outlier_fraction")}[n.model]
    noise = {k: getattr(n, k) for k in (*keys, "dropout_probability")
             if k in keys or getattr(n, k)}
    errors = {k: v for k, v in asdict(sc.calibration_error).items() if k != "scale" and v}
    if errors and sc.calibration_error.scale != 1:
        errors["scale"] = sc.calibration_error.scale
    task = sc.task
    out = {
        "robot": f"{robot} (leg radius {g.leg_radius * 1e3:g} mm, strokes [{lo:g}, {hi:g}] "
                 f"mm), dt {sc.dt * 1e3:g} ms",
        "camera": f"{cam_name} ({cam.kind}, {cam.width}x{cam.height} px, fx "
                  f"{cam.K[0, 0]:.1f} px)",
        "sensor": sc.sensor + (f" ({sc.image.background}, blur {sc.image.blur_px:g} px, "
                               f"noise {sc.image.noise_std:g})" if sc.sensor == "image"
                               else "") + f", teach frames {sc.teach_frames}",
        "noise": n.model + (f": {_nonzero(noise)}" if noise else "")
                 + ("" if n.on_goal or n.model == "none" else ", not on the goal"),
        "calibration error": _nonzero(errors),
        "calibration": sc.calibration.method + (
            f" ({Path(str(sc.calibration.file)).name})" if sc.calibration.method == "file"
            else f" ({sc.calibration.configurations}, {sc.calibration.solver})"
            if sc.calibration.method == "linear" else ""),
        "task": f"{task.kind}, {task.max_steps} steps"
                + (" (fixed duration)" if task.fixed_duration else "")
                + f", tolerances {task.position_tolerance_mm:g} mm and "
                  f"{task.orientation_tolerance_deg:g} deg"
                + (f" for {task.settle_steps} periods" if task.settle_steps > 1 else ""),
        "goal": ("swept (task.goal)" if "task.goal" in sc.sweep_axes
                 else GOAL_TEXT[sc.task.goal]),
        "trials": f"{sc.trials} per sweep point and controller, seed {sc.seed}",
    }
    if getattr(sc, "robot_model", None):  # the controllers' masses and drives
        m = sc.model_data
        out["controllers' model"] = (
            f"{Path(sc.robot_model).name} ({m.name}: [inertia] and [drives], platform "
            f"{m.inertia.platform_mass:g} kg, force limit "
            f"{float(m.drives.force_limit.max()):g} N; the world's truth is the robot's)")
    if getattr(sc, "payload", None) is not None:
        p = sc.payload
        out["payload"] = (f"{p.mass_kg:g} kg, centre of mass {list(p.com_mm)} mm (platform "
                          f"frame), inertia {list(p.inertia_kg_m2)} kg m^2")
    for key, values in sc.sweep_axes.items():
        out[f"swept {key}"] = ", ".join(f"{v:g}" if isinstance(v, float) else str(v)
                                        for v in values)
    return out
