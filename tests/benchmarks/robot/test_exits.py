"""The session's signal handlers (benchmarks.robot.exits), with real signals to this
process."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from benchmarks.robot.exits import (
    SESSION_SIGNALS,
    ServoExit,
    SessionStop,
    SignalGuard,
    exit_for_signal,
)


def test_exit_codes_of_the_signals() -> None:
    assert exit_for_signal(signal.SIGINT) is ServoExit.INTERRUPTED == 130
    assert exit_for_signal(signal.SIGTERM) is ServoExit.TERMINATED == 143
    assert exit_for_signal(signal.SIGHUP) is ServoExit.HANGUP == 129


def test_outside_the_loop_a_signal_stops_at_once_and_handlers_are_restored() -> None:
    before = {s: signal.getsignal(s) for s in SESSION_SIGNALS}
    with SignalGuard(lambda text: None) as guard, pytest.raises(SessionStop) as stop:
        os.kill(os.getpid(), signal.SIGTERM)
    assert stop.value.code is ServoExit.TERMINATED and stop.value.reason == "SIGTERM received"
    assert guard.received == ["SIGTERM"]
    assert {s: signal.getsignal(s) for s in SESSION_SIGNALS} == before


def test_in_the_loop_the_first_signal_waits_for_the_period_the_second_does_not() -> None:
    with SignalGuard(lambda text: None) as guard:
        guard.in_loop = True
        os.kill(os.getpid(), signal.SIGHUP)  # noted, not raised
        with pytest.raises(SessionStop) as stop:
            guard(3, np.zeros(6), None)  # the next period's check
        assert stop.value.code is ServoExit.HANGUP
        with pytest.raises(SessionStop) as again:
            os.kill(os.getpid(), signal.SIGINT)
        assert again.value.code is ServoExit.INTERRUPTED


def test_a_signal_during_the_shutdown_never_skips_the_halt() -> None:
    said: list[str] = []
    with SignalGuard(said.append) as guard:
        guard.shutting_down = True
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGTERM)
        guard(0, np.zeros(6), None)  # nothing raised either
    assert guard.received == ["SIGINT", "SIGTERM"]
    assert said == [f"{name} received during the shutdown: the robot is being halted first"
                    for name in ("SIGINT", "SIGTERM")]
