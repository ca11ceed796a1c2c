"""Work units carry their data: a Dask worker that cannot see the scenario's folder runs a
study of the user's own robot and camera (a real scheduler and a real worker process,
started in another directory after the files were moved away)."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.sim import run_trials
from benchmarks.study.runner import dask_workers, plan, read_results, run_units
from benchmarks.study.scenario import load_scenario
from hexapod import deltalab
from hexapod.exceptions import ConfigFileError
from vision.cameras import front_camera


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _write_study(folder: Path) -> Path:
    folder.mkdir()
    robot = deltalab().replace(leg_radius=0.012, name="my-robot")
    robot.to_toml(folder / "robot.toml")
    front_camera(robot).to_toml(folder / "camera.toml")
    study = folder / "my.toml"
    study.write_text('name = "mine"\nseed = 3\ntrials = 4\n'
                     'controllers = [{name = "leg-edge", gain = 5.0}]\n'
                     '[robot]\ngeometry = "robot.toml"\n[camera]\nfile = "camera.toml"\n'
                     '[task]\nmax_steps = 200\nposition_tolerance_mm = 0.5\n'
                     'orientation_tolerance_deg = 0.05\n')
    return study


@pytest.mark.slow
def test_a_worker_that_cannot_see_the_files_runs_the_study(tmp_path: Path) -> None:
    study = _write_study(tmp_path / "study")
    sc = load_scenario(study)  # the client reads the files here, once
    units = plan([sc], chunk_size=2, record_trials=1)
    (tmp_path / "study").rename(tmp_path / "moved-away")
    assert not study.exists()
    # without the data the work unit carries, the files would be needed (and are gone)
    bare = replace(sc, geometry_data=None, camera_data=None)
    with pytest.raises(ConfigFileError, match=r"robot\.toml: file not found"):
        run_trials(bare, 0, [0])

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler",
                               "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              cwd=elsewhere, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", f"tcp://127.0.0.1:{port}",
             "--nworkers", "1", "--nthreads", "2", "--no-dashboard", "--local-directory",
             str(elsewhere)], cwd=elsewhere, env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL))
        from dask.distributed import Client

        deadline = time.monotonic() + 60
        while True:  # the worker has joined the scheduler
            try:
                with Client(f"tcp://127.0.0.1:{port}", timeout=5) as client:
                    if client.scheduler_info()["workers"]:
                        break
            except OSError:
                pass
            assert time.monotonic() < deadline, "the Dask worker did not start"
            time.sleep(0.5)
        # with --dask ADDRESS the units are cut for the scheduler's threads (they were cut
        # for --workers, default 1: each unit a whole controller's trials)
        assert dask_workers(f"tcp://127.0.0.1:{port}", 1) == 2
        out = tmp_path / "out"
        assert run_units(units, out, dask=f"tcp://127.0.0.1:{port}") == 4
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=20)
    rows = read_results(out)
    assert len(rows) == 4
    assert all(r["failure"] is None or r["failure"].startswith("not converged") for r in rows)
    assert any(r["converged"] for r in rows)
    record = np.load(next((out / "trials").glob("*.npz")))
    assert float(record["leg_radius"]) == 0.012, "the record holds the user's robot"
