"""The lines ``hexapod-bench check`` prints (:func:`describe`): the robot, its dynamics,
the workspace, what the camera sees, the problems and the verdict."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.study.setup_check import SetupReport
from hexapod.geometry import HexapodGeometry

if TYPE_CHECKING:
    from benchmarks.study.check_command import Setup


def _f(x: float, digits: int = 1) -> str:
    return "-" if not np.isfinite(x) else f"{x:.{digits}f}"


def _per_leg(values: np.ndarray, scale: float, unit: str) -> str:
    """One value when the six legs agree, else the six [unit]."""
    v = np.asarray(values, dtype=float) * scale
    if np.all(v == v[0]):
        return f"{v[0]:g} {unit}"
    return "[" + ", ".join(f"{x:g}" for x in v) + f"] {unit}"


def _dynamics_lines(g: HexapodGeometry, note: str | None) -> list[str]:
    """The masses and drives the dynamic world and the force laws use, and where they
    come from (the robot file's tables, or the stated assumptions; ``note``: a
    scenario's change to the drives)."""
    m, d = g.inertia, g.drives
    extra = [f"  {note}"] if note else []
    masses = f"[inertia] in {m.source}" if m.source else "assumed: no [inertia] table"
    drives = f"[drives] in {d.source}" if d.source else "assumed: no [drives] table"
    return [
        "Dynamics (the dynamic world, the force controllers, drive_model = \"lag\"):",
        f"  masses: platform {m.platform_mass:g} kg, per leg {m.body_mass:g} kg body + "
        f"{m.rod_mass:g} kg rod ({masses})",
        f"  drives ({drives}): "
        f"{d.mode} mode, force limit {_per_leg(d.force_limit, 1, 'N')}, velocity loop "
        f"{_per_leg(d.velocity_bandwidth, 1, 'Hz')}, rotor inertia "
        f"{_per_leg(d.rotor_inertia, 1, 'kg')}, viscous {_per_leg(d.viscous, 1, 'N s/m')}, "
        f"Coulomb {_per_leg(d.coulomb, 1, 'N')}, encoders "
        f"{_per_leg(d.encoder_resolution, 1e6, 'um')}", *extra, ""]


def describe(setup: Setup, report: SetupReport, source: str,
             extra: list[str] | None = None, warned: int = 0) -> list[str]:
    """The lines ``check`` prints (``extra``: lines before the problems, a trajectory
    task's references; ``warned``: how many warnings about the study's files were
    printed first)."""
    g, cam = setup.geometry, setup.camera
    base_r = np.linalg.norm(g.base_points[:, :2], axis=1)
    plat_r = np.linalg.norm(g.platform_points[:, :2], axis=1)
    lines = [f"{source}: a {setup.kind} file" if setup.kind != "scenario" or Path(
        source).exists() else f"{source}: a built-in scenario", *setup.notes, "",
        f"Robot '{g.name}': base radius {_f(base_r.mean() * 1e3)} mm, platform radius "
        f"{_f(plat_r.mean() * 1e3)} mm, stroke {g.q_min * 1e3:g}-{g.q_max * 1e3:g} mm, leg "
        f"radius {g.leg_radius * 1e3:g} mm, speed limit {g.max_speed * 1e3:g} mm/s",
        *(["  home pose: none (the legs cannot all be within the stroke: the error below)"]
          if not np.all((report.home_lengths_mm >= g.q_min * 1e3 - 1e-9)
                        & (report.home_lengths_mm <= g.q_max * 1e3 + 1e-9)) else [
            f"  home pose: platform parallel to the base, centred, "
            f"{_f(report.home_height_mm)} mm above it",
            "  leg lengths at home [mm]: " + ", ".join(
                f"{i}: {_f(q)}" for i, q in enumerate(report.home_lengths_mm))]), ""]
    lines += _dynamics_lines(g, setup.drives_note)
    mt, ma, mm = report.box
    r = report.translation_range_mm
    lines += [
        f"Workspace (task box: within {mt:g} mm and {ma:g} deg of home, {mm:g} mm from the "
        "stroke limits):",
        f"  {100 * report.fraction:.1f} % of {report.samples} random poses keep every leg "
        "inside its stroke",
        "  their range from home [mm]: " + ", ".join(
            f"{a} {_f(r[k, 0])} to {_f(r[k, 1])}" for k, a in enumerate("xyz"))
        + f"; rotations up to {_f(report.max_angle_reached_deg)} deg",
        "  reach from home along one axis [mm]: " + ", ".join(
            f"{a} {_f(v)}" for a, v in zip(("+x", "-x", "+y", "-y", "+z", "-z"),
                                           report.reach_mm, strict=True))
        + "; about one axis [deg]: " + ", ".join(
            f"{a} {_f(v)}" for a, v in zip("xyz", report.reach_deg, strict=True)), ""]
    lines += camera_lines(cam, report)
    lines += [f"  over the workspace: all 12 edges seen at {100 * report.poses_all_visible:.1f}"
              f" % of the reachable poses, none at {100 * report.poses_blind:.1f} %; least "
              f"seen edge: {100 * float(np.min(report.view_fraction)):.1f} % of the poses",
              (f"  edge interaction at home: condition number {_f(report.edge_condition, 1)} "
               f"(smallest/largest singular value {report.edge_ratio:.2e})"
               if np.isfinite(report.edge_ratio) else
               "  edge interaction at home: none (no edge seen at home)")]
    if setup.needs_camera is not None:
        lines.append("  controllers that need the camera: "
                     + (", ".join(setup.needs_camera) or "none"))
    lines.append("")
    lines += extra or []
    if report.problems:
        lines.append("Problems:")
        lines += [f"  {p.severity}: {p.text}" for p in report.problems]
    elif warned:  # ("No problem found." under an unstable gain's warning read as clear)
        lines.append(f"No problem found in the setup; {warned} warning(s) about the study "
                     "above (stderr).")
    else:
        lines.append("No problem found.")
    lines.append("The setup can run." if report.can_run else
                 "The setup cannot run: every trial would fail (fix the errors above).")
    return lines


#: How each end of an edge is said (:func:`benchmarks.study.setup_check.end_status`).
END_TEXT = {"image": "in the image", "outside": "outside the image",
            "far": "far outside the image", "behind": "behind the camera",
            "unimaged": "beyond the lens's field of view",
            "inside-leg": "no edge (the camera is inside the leg's cylinder)"}


def _end(where: str, pixel: np.ndarray) -> str:
    """One end of an edge: its pixel only where it is in the image or near it."""
    if where in ("image", "outside"):
        return f"{END_TEXT[where]} ({_f(pixel[0])}, {_f(pixel[1])})"
    return END_TEXT[where]


def camera_lines(cam: Any, report: SetupReport) -> list[str]:
    """The camera's part of ``check``: the edges seen at home, each end of each edge
    said where it is (in the image with its pixel, outside the image, behind the
    camera...), never a pixel of a point that is not in view as if it were."""
    from vision.legs import DEFAULT_MIN_VISIBLE_FRACTION

    seen = report.home_visible
    whole = seen & np.all(report.home_ends == "image", axis=-1)
    lines = [f"Camera '{cam.name}' ({cam.kind}, {cam.width}x{cam.height} px, fx "
             f"{cam.K[0, 0]:.1f} px)",
             f"  at home it sees {int(seen.sum())} of 12 leg edges ({int(whole.sum())} "
             f"with both ends in the image, {int((seen & ~whole).sum())} with an end out of it); "
             "an edge is "
             f"seen when at least {100 * DEFAULT_MIN_VISIBLE_FRACTION:.0f} % of its length "
             "is in view (imaged, in the image, not hidden); its ends (base, platform):"]
    for i in range(6):
        for j in range(2):
            pct = 100 * float(report.home_fraction[i, j])
            state = (f"seen, {pct:.0f} % in view" if seen[i, j] else
                     f"not seen ({pct:.0f} % in view)")
            ends = [_end(str(report.home_ends[i, j, k]), report.home_pixels[i, j, k])
                    for k in range(2)]
            if ends[0] == ends[1] and not ends[0].endswith(")"):
                ends_text = f"both ends {ends[0]}"
            else:
                ends_text = f"base end {ends[0]}, platform end {ends[1]}"
            lines.append(f"    leg {i} edge {j}: {state}; {ends_text}")
    return lines
