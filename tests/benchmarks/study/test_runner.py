"""The runner: determinism across executors and chunkings, streaming, resume, failures."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.sim import stepper
from benchmarks.sim.world import make_trials
from benchmarks.study.runner import _group, _take, execute, plan, read_results, run_units
from benchmarks.study.scenario import builtin_scenarios, parse_scenario

JOINTS = "tests.benchmarks.plugins:ProportionalJoints"
CRASH = "tests.benchmarks.plugins:CrashOnSomeTrials"

#: Fields that legitimately differ between runs (timings, executor).
VOLATILE = {"step_time_us", "backend"}


def _scenario(trials: int = 6, **extra: object) -> object:
    table = {
        "name": "runner-test", "seed": 3, "trials": trials,
        "controllers": [{"name": JOINTS, "gain": 5.0}, {"name": "leg-edge", "gain": 5.0}],
        "noise": {"model": "rotation", "amplitude_deg": [0.0, 0.05]},
        "calibration_error": {"base_points_mm": 0.5},
        "task": {"max_steps": 150, "position_tolerance_mm": 0.5,
                 "orientation_tolerance_deg": 0.05},
    }
    table.update(extra)
    return parse_scenario(table, "runner-test.toml")


def _stable(rows: list[dict]) -> list[dict]:
    out = [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]
    return sorted(out, key=lambda r: (r["point"], r["controller"], r["trial"]))


@pytest.mark.slow
def test_results_identical_across_executors_and_chunkings(tmp_path: Path) -> None:
    sc = _scenario()
    runs = {
        "inline-chunk1": dict(chunk=1, workers=1, dask=None),
        "inline-chunk4": dict(chunk=4, workers=1, dask=None),
        "pool-2": dict(chunk=2, workers=2, dask=None),
        "dask-local": dict(chunk=3, workers=2, dask="local"),
    }
    results = {}
    for name, cfg in runs.items():
        out = tmp_path / name
        units = plan([sc], chunk_size=cfg["chunk"], record_trials=0)
        n = run_units(units, out, workers=cfg["workers"], dask=cfg["dask"])
        assert n == 2 * 2 * 6
        results[name] = _stable(read_results(out))
    reference = results["inline-chunk1"]
    assert len(reference) == 24
    assert any(r["converged"] for r in reference)
    for name, rows in results.items():
        assert rows == reference, f"{name} differs from the in-process run"


def test_the_controllers_of_a_point_calibrate_and_draw_its_trials_once(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """In one process, the units of a sweep point's controllers take the trials (and the
    per-trial calibrations) drawn for its first: one draw per point."""
    calls: list[tuple[int, ...]] = []

    def counted(sc: Any, trials: list[int], *args: Any) -> Any:
        calls.append(tuple(trials))
        return make_trials(sc, trials, *args)

    monkeypatch.setattr(stepper, "make_trials", counted)
    stepper.forget_trials()
    sc = _scenario(trials=2, calibration={"method": "linear", "configurations": "extremal"},
                   task={"max_steps": 5})
    units = plan([sc], chunk_size=2, record_trials=0)
    rows = [row for u in units for row in execute(u)[0]]
    assert len(units) == 4 and len(rows) == 8
    assert all(r["calibration_configurations"] == 64 for r in rows)  # calibrated
    assert calls == [(0, 1), (0, 1)]  # 2 noise points x 2 controllers: 2 draws


def test_a_worker_keeps_to_its_controller_while_it_has_units() -> None:
    """The pool's next unit for a worker: one of the group (sweep point, controller) it
    ran last, else one of a group no worker runs, else the first left; every unit once."""
    queue = plan([_scenario(trials=4)], chunk_size=2, record_trials=0)
    assert len({_group(u) for u in queue}) == 4 and len(queue) == 8
    first = _take(queue, None, set())
    second = _take(queue, None, {_group(first)})
    assert _group(second) != _group(first)  # the second worker on another controller
    again = _take(queue, first, {_group(second)})
    assert _group(again) == _group(first) and again.trials != first.trials
    other = _take(queue, again, {_group(second)})  # first's group done: a free group
    assert _group(other) not in {_group(first), _group(second)}
    rest = [_take(queue, other, {_group(second)}) for _ in range(len(queue))]
    assert not queue and len({(_group(u), u.trials) for u in [first, second, again, other,
                                                              *rest]}) == 8


@pytest.mark.slow
def test_meanwhile_is_called_once_in_this_process_by_the_pool_only(tmp_path: Path) -> None:
    """``run`` imports the report's drawing modules while the workers run: the hook is
    called once, in a thread of the main process (which keeps feeding the pool), and
    joined before ``run_units`` returns; the rows are those of the in-process run, which
    does not call it. A failing hook is a debug line, not a failed run."""
    import os
    import threading

    units = plan([_scenario(trials=3)], chunk_size=1, record_trials=0)
    calls: list[tuple[int, str, str]] = []
    rows = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        run_units(units, out, workers=workers,
                  meanwhile=lambda w=workers: calls.append(
                      (os.getpid(), threading.current_thread().name, f"w{w}")))
        rows[workers] = _stable(read_results(out))
    assert calls == [(os.getpid(), "meanwhile", "w2")]

    def fails() -> None:
        raise ImportError("no such drawing module")

    assert run_units(units, tmp_path / "fails", workers=2, meanwhile=fails) == 12
    assert rows[2] == rows[1] and len(rows[1]) == 2 * 2 * 3


@pytest.mark.slow
def test_a_crashing_trial_is_recorded_and_the_run_goes_on(tmp_path: Path) -> None:
    sc = _scenario(trials=6, controllers=[{"name": CRASH, "gain": 5.0},
                                          {"name": JOINTS, "gain": 5.0}])
    run_units(plan([sc], chunk_size=6, record_trials=0), tmp_path)
    rows = read_results(tmp_path)
    crash = [r for r in rows if r["controller"] == CRASH]
    fine = [r for r in rows if r["controller"] == JOINTS]
    failed = [r for r in crash if r["failure"] and "deliberate crash" in r["failure"]]
    assert 0 < len(failed) < len(crash), "some (not all) trials of the crashing controller fail"
    assert all(not r["converged"] for r in failed)
    assert len(fine) == 12 and all(r["failure"] is None for r in fine if r["converged"])


def _full_and_half(tmp_path: Path) -> tuple[Any, Path, Path]:
    """A 4-trial scenario run whole into ``full`` and half into ``part`` (a run stopped
    halfway)."""
    sc = _scenario(trials=4)
    full = tmp_path / "full"
    run_units(plan([sc], chunk_size=2, record_trials=0), full)
    part = tmp_path / "part"
    units = plan([sc], chunk_size=2, record_trials=0)
    run_units(units[: len(units) // 2], part)
    return sc, full, part


@pytest.mark.slow
def test_resume_after_partial_run_redoes_nothing(tmp_path: Path) -> None:
    sc, full, part = _full_and_half(tmp_path)
    first = read_results(part)
    assert 0 < len(first) < 16
    # a partial line from a killed writer is dropped, not fatal
    with (part / "results.jsonl").open("a") as f:
        f.write('{"scenario": "runner-test", "trunc')
    from benchmarks.study.runner import completed_keys

    todo = plan([sc], chunk_size=2, record_trials=0, done=completed_keys(part))
    assert sum(len(u.trials) for u in todo) == 16 - len(first)
    run_units(todo, part)
    assert _stable(read_results(part)) == _stable(read_results(full))


def test_a_whole_last_row_without_its_newline_is_kept_on_resume(tmp_path: Path) -> None:
    """A run killed between a row and its newline: the row is whole, counted done by the
    resume, and kept (the repair dropped it after the resume had counted it: the resumed
    run ended with a trial missing and exit 0)."""
    from benchmarks.study.runner import completed_keys

    sc, full, part = _full_and_half(tmp_path)
    path = part / "results.jsonl"
    path.write_bytes(path.read_bytes()[:-1])  # the last row whole, its newline not written
    done = completed_keys(part)
    run_units(plan([sc], chunk_size=2, record_trials=0, done=done), part)
    assert _stable(read_results(part)) == _stable(read_results(full))  # none missing


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.parametrize(("signum", "status", "word", "executor"), [
    (signal.SIGINT, 130, "interrupted", "inline"), (signal.SIGTERM, 143, "terminated", "pool"),
    (signal.SIGINT, 130, "interrupted", "dask")])
def test_cli_interrupted_run_resumes(tmp_path: Path, signum: int, status: int, word: str,
                                     executor: str) -> None:
    """Ctrl-C (to the terminal's process group: every process of the run gets it), or
    SIGTERM (a service manager's or a scheduler's stop) to the run's process alone: the
    rows written are kept, the report is written, the hint resumes the run, no worker
    outlives it, and no process prints a traceback (a local Dask cluster's did)."""
    scen = tmp_path / "long.toml"
    scen.write_text(
        'name = "long"\nseed = 5\ntrials = 40\ncontrollers = ["leg-edge"]\n'
        '[task]\nmax_steps = 120\n[noise]\nmodel = "rotation"\namplitude_deg = 0.02\n')
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "benchmarks.cli", "run", str(scen), "--out", str(out),
           "--chunk", "1", "--record", "0", "--no-progress",
           *{"inline": [], "pool": ["--workers", "2"],
             "dask": ["--workers", "2", "--dask", "local"]}[executor]]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)  # its own group, as in a terminal
    results = out / "results.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if results.exists() and len(results.read_text().splitlines()) >= 3:
            break
        time.sleep(0.05)
    children = _descendants(proc.pid)
    assert len(children) >= (2 if executor != "inline" else 0), children
    if signum == signal.SIGINT:
        os.killpg(proc.pid, signum)  # Ctrl-C: the terminal signals the whole group
    else:
        proc.send_signal(signum)
    stdout, err = proc.communicate(timeout=60)
    assert "Traceback" not in err.decode(), err.decode()[-3000:]
    written = read_results(out)
    assert 3 <= len(written) < 40, err.decode()[-2000:]
    assert proc.returncode == status, err.decode()[-2000:]
    # the summary counts what was written, not what was planned
    text = " ".join(stdout.decode().split())
    assert f"{word}: {len(written)} of 40 trials written" in text, text[-2000:]
    assert "--resume" in text.split(f"{word}:")[1].split("\n")[0]
    deadline = time.monotonic() + 10
    while any(Path(f"/proc/{pid}").exists() for pid in children) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [pid for pid in children if Path(f"/proc/{pid}").exists()], "a worker lingers"
    assert f"{len(written)} of 40 trials in" in text, text[-2000:]
    # without --resume the directory is protected
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress"]) == 2
    assert cli_main(["run", str(scen), "--out", str(out), "--resume", "--chunk", "5",
                     "--record", "0", "--no-progress"]) == 0
    rows = read_results(out)
    keys = [(r["trial"]) for r in rows]
    assert sorted(keys) == list(range(40)), "every trial exactly once"
    assert (out / "report.md").exists()


def _descendants(pid: int) -> list[int]:
    """The processes ``pid`` started, and theirs (Linux's ``/proc``)."""
    found: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (int(c) for c in (task / "children").read_text().split()):
            found += [child, *_descendants(child)]
    return found


def test_results_rows_have_the_documented_fields(tmp_path: Path) -> None:
    sc = _scenario(trials=2)
    run_units(plan([sc], chunk_size=2, record_trials=1), tmp_path)
    rows = read_results(tmp_path)
    for key in ("scenario", "controller", "trial", "noise_amplitude_deg", "converged", "steps",
                "final_position_error_mm", "final_orientation_error_deg", "stroke_violations",
                "step_time_us", "failure", "controller_package", "controller_version",
                "hidden_edge_periods", "goal"):
        assert all(key in r for r in rows), key
    assert json.loads((tmp_path / "results.jsonl").read_text().splitlines()[0])
    assert list((tmp_path / "trials").glob("*.npz")), "trial 0 is recorded"


@pytest.mark.slow
def test_run_goal_runs_the_scenario_in_that_setting(tmp_path: Path) -> None:
    """``run --goal taught``: every row, the run's settings, the report and the runnable
    copy say ``taught``; the joint-space law then ends at the goal of quick's world (its
    only imperfection for an encoder law is the model error: no encoder noise)."""
    out = tmp_path / "taught"
    assert cli_main(["run", "quick", "--out", str(out), "--trials", "2", "--no-progress",
                     "--controllers", "joint-space", "--goal", "taught"]) == 0
    rows = read_results(out)
    assert [r["goal"] for r in rows] == ["taught", "taught"]
    assert all(r["final_position_error_mm"] < 1e-6 for r in rows), rows
    meta = json.loads((out / "run.json").read_text())
    assert meta["scenarios"]["quick"]["settings"]["goal"].startswith("taught:")
    assert "taught: images and encoders recorded" in (out / "report.md").read_text()
    assert 'goal = "taught"' in (out / "inputs" / "quick" / "scenario.toml").read_text()


#: Control periods of the end-to-end runs: 120, fewer for the scenarios whose periods are
#: costly (1000 frames/s cameras, rendered images, 1 ms physics, 64 sweep points); every
#: controller at every sweep point still runs, records and is reported.
END_TO_END_STEPS = {"camera-latency": 30, "fisheye-close": 40, "quick-dynamic": 40,
                    "calibration-map": 30, "andreff2006-images-distorted": 40,
                    "camera-latency-p2p": 40,
                    "inertia-error": 40, "paccot2008-tracking": 40, "mpc-drives": 20,
                    "mpc-drives-tracking": 20,
                    # (5: its 85 kg point sags onto an end stop within 0.4 s: the drives
                    # cannot hold it, the failure the study measures)
                    "payload-saturation": 5}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(builtin_scenarios()))
def test_builtin_scenario_end_to_end(name: str, tmp_path: Path) -> None:
    """Each built-in scenario runs (1 trial per controller and sweep point): rows that
    converged or ran out of steps, never two for the same controller and sweep point,
    and a report naming the scenario and each controller (the ``report`` command on a
    run's directory: test_report_command_rebuilds_the_report)."""
    out = tmp_path / name
    steps = END_TO_END_STEPS.get(name, 120)
    code = cli_main(["run", name, "--out", str(out), "--trials", "1", "--no-progress",
                     "--record", "1", "--max-steps", str(steps)])
    assert code == 0
    rows = read_results(out)
    assert rows and all(r["failure"] is None or "not converged" in r["failure"] for r in rows)
    assert len({(r["point"], r["controller"]) for r in rows}) == len(rows)
    report = (out / "report.md").read_text()
    assert f"Scenario `{name}`" in report
    assert all(c in report for c in {r["controller"] for r in rows})


@pytest.mark.slow
def test_report_command_rebuilds_the_report(tmp_path: Path) -> None:
    """``hexapod-bench report DIR`` on a finished run's directory rewrites the run's own
    report: the same text but for the time it was generated and the report command added
    to the commands that wrote the directory."""
    out = tmp_path / "quick"
    assert cli_main(["run", "quick", "--out", str(out), "--trials", "2", "--no-progress",
                     "--record", "1", "--max-steps", "60"]) == 0
    first = (out / "report.md").read_text().splitlines()
    assert cli_main(["report", str(out)]) == 0
    again = (out / "report.md").read_text().splitlines()
    added = [line for line in again if line.startswith(f"2. `hexapod-bench report {out}` (")]
    assert len(added) == 1 and added[0].endswith(": rebuilt report.md and its figures")
    again.remove(added[0])
    assert len(first) == len(again) > 20
    differ = [(a, b) for a, b in zip(first, again, strict=True) if a != b]
    assert all(a.startswith("Generated ") for a, _ in differ), differ


@pytest.mark.slow
def test_a_second_run_on_a_locked_directory_is_refused(tmp_path: Path) -> None:
    """Two real processes: the second refuses while the first holds DIR/.lock, naming it."""
    scen = tmp_path / "long.toml"
    scen.write_text(
        'name = "long"\nseed = 5\ntrials = 200\ncontrollers = ["leg-edge"]\n'
        '[task]\nmax_steps = 200\n')
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    run = [sys.executable, "-m", "benchmarks.cli", "run", str(scen), "--out", str(out),
           "--chunk", "1", "--record", "0", "--no-progress"]
    first = subprocess.Popen(run, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        lock = out / ".lock"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (
                lock.exists() and lock.read_text().startswith(str(first.pid))):
            time.sleep(0.05)
        assert lock.read_text().startswith(f"{first.pid} "), "the first run holds the lock"
        for extra in ([], ["--resume"]):  # a resume while the first still runs is refused too
            second = subprocess.run(run + extra, env=env, capture_output=True, text=True,
                                    timeout=120)
            assert first.poll() is None, "the first run was still running"
            assert second.returncode == 2, second.stderr[-2000:]
            assert f"PID {first.pid}" in second.stderr, second.stderr
            assert "another hexapod-bench run" in second.stderr
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    rows = read_results(out)
    keys = [r["trial"] for r in rows]
    assert len(keys) == len(set(keys)), "no trial written twice"
    # released when the holder ends: the directory can be resumed
    assert lock.read_text() == ""
    # (the study it holds: 200 trials; fewer would be another study, refused)
    assert cli_main(["run", str(scen), "--out", str(out), "--resume", "--no-progress"]) == 0
    assert sorted(r["trial"] for r in read_results(out)) == list(range(200))


@pytest.mark.slow
def test_report_ignores_duplicate_rows_and_says_so(tmp_path: Path, capsys: object) -> None:
    sc = _scenario(trials=3)
    run_units(plan([sc], chunk_size=3, record_trials=0), tmp_path)
    path = tmp_path / "results.jsonl"
    lines = path.read_text().splitlines()
    unique = len(lines)
    # the tail of a second run appended into the same file: 5 duplicated keys, one altered
    extra = [json.loads(x) for x in lines[:5]]
    extra[0]["final_position_error_mm"] = 123.0
    with path.open("a") as f:
        for row in extra:
            f.write(json.dumps(row) + "\n")
    assert cli_main(["report", str(tmp_path)]) == 0
    out = capsys.readouterr().out  # type: ignore[attr-defined]
    assert "5 duplicate row(s) ignored" in " ".join(out.split())
    assert "1 of them disagree" in " ".join(out.split())
    report = (tmp_path / "report.md").read_text()
    assert f"({unique} trials)" in report
    assert "**Duplicate rows**: 5 duplicate row(s) ignored" in report
    assert "123.0" not in report


@pytest.mark.realtime
@pytest.mark.slow
def test_a_killed_run_leaves_no_worker_holding_its_lock(tmp_path: Path) -> None:
    """SIGKILL to the run's process alone (an OOM killer, `kill -9 PID`): its pool workers,
    forked with the lock's descriptor, lived on holding it, and --resume was refused
    naming a process that no longer existed. They end with it, and the lock is free."""
    import signal

    from benchmarks.study.results import run_lock

    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "benchmarks.cli", "run", "quick", "--out", str(out),
           "--trials", "400", "--workers", "2", "--chunk", "20", "--no-progress"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    results = out / "results.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (
            results.exists() and len(results.read_text().splitlines()) >= 20):
        time.sleep(0.2)
    children = [int(p) for p in Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
                .read_text().split()]
    assert len(children) >= 2, children  # the pool's workers
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(Path(f"/proc/{c}").exists() for c in children):
        time.sleep(0.1)
    alive = [c for c in children if Path(f"/proc/{c}").exists()
             and "Z" not in Path(f"/proc/{c}/stat").read_text().split()[2]]
    assert alive == [], alive
    with run_lock(out):  # free: a resume may take it
        pass


def test_the_interrupted_run_s_hint_is_its_own_command_with_resume() -> None:
    """(It printed 'hexapod-bench run quick --out DIR --resume' for a run of --seed 7
    --trials 600, a command the resume then refused: '--seed: 7 in the directory, 1
    given'.)"""
    import argparse

    from benchmarks.study.commands import _resume_command

    args = argparse.Namespace(argv=["run", "quick", "--out", "my dir", "--trials", "600",
                                    "--seed", "7"], scenarios=["quick"])
    assert _resume_command(args, Path("my dir")) == \
        "hexapod-bench run quick --out 'my dir' --trials 600 --seed 7 --resume"
    args.argv = [*args.argv, "--resume"]
    assert _resume_command(args, Path("my dir")).count("--resume") == 1
    # tune's candidates' run: the tune command (a run command there was refused)
    args = argparse.Namespace(argv=["tune", "quick", "--controllers", "leg-edge", "--out",
                                    "t"], scenarios=["/abs/quick.toml"])
    assert _resume_command(args, Path("t/candidates")) == \
        "hexapod-bench tune quick --controllers leg-edge --out t --resume"


@pytest.mark.slow  # (3 to 5 s: over the quick tier's budget)
def test_units_run_by_threads_give_the_rows_of_a_serial_run() -> None:
    """The threads of one process (a Dask worker's, two or more by default) share the
    compiled functions: their one set of buffers took the inputs of whichever thread
    wrote last (17 of 40 rows of leg-edge-qp changed with two threads, and changed again
    from run to run). Each function's calls on its buffers hold its lock now."""
    from concurrent.futures import ThreadPoolExecutor

    from benchmarks.study.scenario import load_scenario

    study = load_scenario("quick").with_overrides(trials=24, controllers=["leg-edge-qp"])
    units = plan([study], chunk_size=3, record_trials=0)
    serial = _stable([row for u in units for row in execute(u)[0]])
    with ThreadPoolExecutor(4) as pool:
        threaded = _stable([row for rows, _ in pool.map(execute, units) for row in rows])
    assert len(serial) == 24 and threaded == serial


def test_a_dask_address_that_is_none_is_refused_naming_the_option(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A malformed --dask address was a ValueError traceback (an unreachable one an
    OSError after 30 s naming nothing); a cluster that fails under a run is told apart
    from a unit's own error (which is a row)."""
    from distributed.scheduler import KilledWorker

    from benchmarks.study.runner import _cluster_failure

    code = cli_main(["run", "quick", "--trials", "1", "--out", str(tmp_path / "d"),
                     "--dask", "not an address", "--no-progress"])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 2 and "--dask: no Dask scheduler at 'not an address'" in err, err
    assert "Traceback" not in err
    from distributed.comm.core import CommClosedError

    assert _cluster_failure(KilledWorker("unit", "tcp://w", 3))
    assert _cluster_failure(CommClosedError("in <TCP ...>: Stream is closed"))
    assert not _cluster_failure(ValueError("a unit's own error"))
    # a worker without the scenario's files: the unit's own error, said as it is
    assert not _cluster_failure(FileNotFoundError("robot.toml"))


def test_a_local_dask_run_has_the_workers_it_was_given() -> None:
    """(A scheduler's threads: ``test_remote_workers``, with a real scheduler and worker.)"""
    from benchmarks.study.runner import dask_workers

    assert dask_workers("local", 2) == 2
    assert dask_workers("local", 1) == 1


def test_a_resume_with_another_record_count_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"
    base = ["run", "quick", "--trials", "1", "--controllers", "leg-edge", "--out", str(out),
            "--no-progress"]
    assert cli_main([*base, "--record", "1"]) == 0
    capsys.readouterr()
    assert cli_main([*base, "--trials", "2", "--resume", "--record", "0"]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "warning: --record 0: the directory's run recorded 1 trial(s)" in err, err
    assert json.loads((out / "run.json").read_text())["record"] == 0


@pytest.mark.slow
def test_a_quiet_dask_run_leaves_the_environment_and_logger_as_it_found_them(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A local Dask run without --verbose quiets its cluster's processes through the
    environment and Dask's logger in this process: both had stayed set after the run, so a
    later --verbose run of the same process (and every process it started) stayed quiet."""
    import logging

    import dask.distributed  # (its import sets Dask's logger's level from its configuration)

    monkeypatch.delenv("DASK_LOGGING__DISTRIBUTED", raising=False)
    dask_log = logging.getLogger("distributed")
    monkeypatch.setattr(dask_log, "level", logging.DEBUG)  # (a user's own level)
    seen: list[str | None] = []
    original = dask.distributed.LocalCluster  # (the one the runner starts)

    def cluster(*args: Any, **kwargs: Any) -> Any:
        seen.append(os.environ.get("DASK_LOGGING__DISTRIBUTED"))  # as its processes start
        return original(*args, **kwargs)

    monkeypatch.setattr(dask.distributed, "LocalCluster", cluster)
    units = plan([_scenario(trials=2)], chunk_size=2, record_trials=0)
    assert run_units(units, tmp_path / "o", workers=1, dask="local") == 2 * 2 * 2
    assert seen == ["critical"]  # (pytest's root logger is at WARNING: not --verbose)
    assert "DASK_LOGGING__DISTRIBUTED" not in os.environ
    assert dask_log.level == logging.DEBUG
