"""``hexapod-bench viz``: replay a recorded trial of a run directory (or a servo
session log) in the viewer, or write it as an HTML page with its curves."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from benchmarks.exceptions import BenchmarkError
from benchmarks.study.outdir import OutputFile


def find_record(out: Path, trial: int, controller: str | None = None,
                scenario: str | None = None, point: int | None = None) -> Path:
    """The recorded trial file of a run directory matching the selection.

    Raises:
        BenchmarkError: No such record (listing what is there), or an ambiguous selection.
    """
    from benchmarks.study.outdir import META_FILE
    from benchmarks.study.results import TRIALS_DIR

    folder = out / TRIALS_DIR
    files = sorted(folder.glob("*.npz")) if folder.exists() else []
    if not files:
        recorded = _recorded_count(out)
        if not (out / META_FILE).is_file():  # not a run directory
            what = "no such file or directory" if not out.exists() else (
                "neither a run directory nor a servo session log" if out.is_dir() else
                "not a servo session log (JSON lines: a servo_session header, periods "
                "with step, t_s, lengths_mm)")
            raise BenchmarkError(f"{out}: {what}; viz replays a trial of a run directory "
                                 "(hexapod-bench run --out DIR --record K) or a servo session "
                                 "(its directory, servo-runs/<UTC time>-<controller>/ or "
                                 "servo --out DIR, or its servo.jsonl or servo --log "
                                 "FILE.jsonl)")
        why = " (the run used --record 0)" if recorded == 0 else ""
        raise BenchmarkError(f"{out}: no recorded trial{why}; rerun into a new --out with "
                             "--record K to keep the time series of trials 0 to K-1 of each "
                             "controller")
    matches = []
    for f in files:
        parts = f.stem.split("__")
        if len(parts) != 4:
            continue
        sc, pt, ctrl, k = parts
        if int(k) != trial or (controller and ctrl != controller) or (
                scenario and sc != scenario) or (point is not None and pt != f"p{point}"):
            continue
        matches.append(f)
    if not matches:
        stems = [f.stem.split("__") for f in files]
        stems = [x for x in stems if len(x) == 4]
        for option, col, given in (("--scenario", 0, scenario),
                                   ("--controller", 2, controller),
                                   ("--point", 1, None if point is None else f"p{point}")):
            known = sorted({x[col] for x in stems})
            if given is not None and given not in known:  # no such one at all
                shown = [v[1:] for v in known] if option == "--point" else known
                raise BenchmarkError(f"{out}: {option} {str(given).lstrip('p')}: nothing "
                                     f"recorded under it; recorded: {', '.join(shown)}")
        available = sorted({f.stem for f in files})[:20]
        recorded = _recorded_count(out)
        hint = ""
        if recorded is not None and trial >= recorded:
            hint = (f"; the run kept the time series of trials 0 to {recorded - 1} only "
                    f"(--record {recorded}): rerun into a new --out with --record "
                    f"{trial + 1} to keep trial {trial}")
        raise BenchmarkError(f"{out}: no recorded trial {trial}"
                             + (f" of '{controller}'" if controller else "")
                             + f"{hint}; recorded: {', '.join(available)}")
    if len(matches) > 1:
        names = [m.stem.split("__") for m in matches]
        options = [option for option, k, given in (("--scenario", 0, scenario),
                                                   ("--point", 1, point),
                                                   ("--controller", 2, controller))
                   if given is None and len({n[k] for n in names}) > 1]
        raise BenchmarkError(f"{out}: {len(matches)} records match ("
                             + ", ".join(m.stem for m in matches[:8])
                             + "); choose with " + " and ".join(options))
    return matches[0]


def _recorded_count(out: Path) -> int | None:
    """The ``--record`` of the run (``run.json``), None when unknown."""
    try:
        value = json.loads((out / "run.json").read_text()).get("record")
    except (OSError, ValueError):
        return None
    return value if isinstance(value, int) else None


def cmd_viz(args: argparse.Namespace) -> int:
    """Replay a recorded trial or a servo session (its log, or the session directory
    holding it): live in MeshCat, or as a self-contained HTML file + curves."""
    from benchmarks.robot.replay import find_session_log, load_session
    from benchmarks.study.results import TRIALS_DIR
    from hexapod.visualize import HexapodViewer, load_trial, plot_trial, replay_html

    out = Path(args.dir)
    if args.still is not None and not args.html:
        raise BenchmarkError("--still draws a still into the --html page: give --html FILE "
                             "too (the live view replays the whole trial)")
    session = None if (out / TRIALS_DIR).is_dir() else find_session_log(out)
    path = session or find_record(out, args.trial, args.controller, args.scenario, args.point)
    if args.html:
        from hexapod.outputs import check_replace

        html_path, png_path = Path(args.html), Path(args.html).with_suffix(".png")
        if html_path == png_path:
            raise BenchmarkError(f"--html {args.html}: the curves go beside it as "
                                 f"{png_path.name}; give the page an .html name")
        overwrite = getattr(args, "overwrite", False)
        check_replace(html_path, overwrite, kind="HTML")
        check_replace(png_path, overwrite, kind="PNG")
    if session is not None:
        record = load_session(session, getattr(args, "geometry", None),
                              getattr(args, "camera_file", None),
                              getattr(args, "camera_pose", None), getattr(args, "goal", None))
    else:
        record = load_trial(path)
    if args.html:
        if args.still is not None and not -record.frames <= args.still < record.frames:
            raise BenchmarkError(f"--still {args.still}: {record.title} has periods 0 to "
                                 f"{record.frames - 1} (negative values count from the "
                                 "end: -1 is the last)")
        html_path.parent.mkdir(parents=True, exist_ok=True)
        html = replay_html(record, html_path, frame=args.still)
        png = plot_trial(record, png_path)
        print(f"{record.title}: wrote {html} (open it in a browser, no network needed) "
              f"and {png}")
        return 0
    a = record.arrays
    with HexapodViewer(record.geometry) as viewer:
        viewer.show_camera(a["camera_from_base"], a["camera_K"], int(a["camera_size"][0]),
                           int(a["camera_size"][1]), str(a["camera_kind"]))
        viewer.show_goal(a["goal_rotation"], a["goal_translation"])
        print(f"{record.title}: MeshCat viewer at {viewer.url()} (Ctrl-C to stop)")
        dt = float(a["t"][1] - a["t"][0]) if record.frames > 1 else 0.02
        try:
            for k in range(record.frames):
                viewer.display(a["rotations"][k], a["translations"][k], a["edge_visible"][k],
                               force=True)
                time.sleep(dt)
            time.sleep(args.hold)
        except KeyboardInterrupt:
            pass
    return 0


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The arguments of ``hexapod-bench viz``."""
    s.add_argument("dir", help="a run directory, or a servo session: its directory "
                               "(servo-runs/..., servo --out DIR) or its log (servo.jsonl, "
                               "servo --log FILE.jsonl)")
    s.add_argument("--trial", type=int, default=0)
    s.add_argument("--controller", help="controller label")
    s.add_argument("--scenario", help="scenario name (when the run has several)")
    s.add_argument("--point", type=int, help="sweep point index")
    s.add_argument("--html", action=OutputFile, metavar="FILE",
                   help="write a self-contained HTML animation (+ a PNG of the curves beside "
                        "it) instead of the live view")
    s.add_argument("--still", type=int, help="with --html: a still of this control period "
                                             "(-1: the last)")
    s.add_argument("--overwrite", action="store_true",
                   help="with --html: replace the file (and the PNG beside it) even if "
                        "hexapod-bench did not write it")
    s.add_argument("--hold", type=float, default=5.0,
                   help="live view: seconds to keep the server after the replay")
    session = s.add_argument_group("servo session (default: what its record's header "
                                   "says the session was run with)")
    session.add_argument("--geometry",
                         help="nominal robot: a geometry TOML file or a preset (default the "
                              "header's, else deltalab)")
    session.add_argument("--camera-file",
                         help="camera model drawn (default the header's, else front)")
    session.add_argument("--camera-pose", metavar="PRESET|TOML",
                         help="with a calibration file: the camera's pose (default the "
                              "header's)")
    session.add_argument("--goal", metavar="FILE",
                         help="a goal file (the errors are measured to it; default the "
                              "header's goal lengths, else the last period's pose)")
