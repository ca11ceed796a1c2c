"""The examples at the end of each ``hexapod-bench COMMAND --help`` (every one is parsed by
a test, and every scenario it names is a built-in one), and the help formatter that
prints them as written."""

from __future__ import annotations

import argparse

#: A few typical command lines of each subcommand, with what each does.
EXAMPLES: dict[str, list[tuple[str, str]]] = {
    "list": [("hexapod-bench list", "the built-in scenarios and controllers"),
             ("hexapod-bench list --options vision-ctc", "a controller's options")],
    "run": [("hexapod-bench run quick --out runs/quick", "a small study"),
            ("hexapod-bench run paccot2008-tracking --trials 200 --workers 2 --out runs/paccot",
             "a paper's study at full size"),
            ("hexapod-bench run quick --out runs/quick --resume",
             "finish an interrupted run (its own command with --resume)"),
            ("hexapod-bench run my-study.toml --controllers leg-edge,leg-edge-qp --out runs/mine",
             "a scenario file of one's own, two controllers")],
    "tune": [("hexapod-bench tune inertia-error --controllers computed-torque,leg-edge "
              "--trials 5 --candidates 8 --out tune-inertia",
              "matched tuning on held-out trials, then run with --options-file "
              "tune-inertia/tuned.toml")],
    "check": [("hexapod-bench check quick", "a built-in scenario"),
              ("hexapod-bench check my-hexapod.toml --picture home.png",
               "a robot file, with the camera's view of it at home")],
    "report": [("hexapod-bench report runs/quick", "report.md again from the rows")],
    "compare": [("hexapod-bench compare runs/quick --baseline leg-edge",
                 "paired tests between the controllers of one run"),
                ("hexapod-bench compare runs/before runs/after --check",
                 "two runs of the same scenarios: regressions, determinism")],
    "export": [("hexapod-bench export runs/quick --parquet quick.parquet",
                "every trial as a table row")],
    "reproduce": [("hexapod-bench reproduce seed001 --quick --out repro",
                   "a paper's figures at reduced counts, paper and framework side by side")],
    "calibrate": [("hexapod-bench calibrate quick --out cal",
                   "the base points from the simulated robot's own images"),
                  ("hexapod-bench calibrate my-study.toml --out cal --observations "
                   "measured.json", "from a real robot's measured edges and lengths")],
    "identify": [("hexapod-bench identify deltalab --truth deltalab-heavy.toml --out ident",
                  "a simulated robot's inertia, friction and rotor inertia")],
    "servo": [("hexapod-bench servo --backend emulator --camera sim "
               "--simulated-camera-on-real-robot --controller leg-edge --goal goal.toml",
               "one controller on the emulated robot"),
              ("hexapod-bench servo --teach --goal goal.toml --backend emulator --camera sim "
               "--simulated-camera-on-real-robot", "record a goal where the robot stands")],
    "conformance": [("hexapod-bench conformance emulator",
                     "the emulated robot's backend against the simulator")],
    "viz": [("hexapod-bench viz runs/quick --trial 0 --controller leg-edge --html trial.html",
             "a recorded trial as a page that plays without a server")],
    "perf": [("hexapod-bench perf controllers", "each controller's step time"),
             ("hexapod-bench perf dynamics --energy --repeats 100",
              "the dynamics against a second formulation")],
    "warm": [("hexapod-bench warm", "compile every built-in scenario's C once")],
}


def epilog(command: str, before: str | None = None) -> str | None:
    """``before`` (a command's own epilog) followed by its :data:`EXAMPLES`."""
    examples = EXAMPLES.get(command)
    if not examples:
        return before
    lines = ["examples:"]
    for line, what in examples:
        lines += [f"  {line}", f"      {what}"]
    text = "\n".join(lines)
    return text if before is None else f"{before}\n\n{text}"


class ExamplesFormatter(argparse.HelpFormatter):
    """argparse's formatter, except that a text starting with ``examples:`` keeps its
    lines as written (a command line is not re-wrapped)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        head, sep, examples = text.partition("examples:\n")
        if not sep:
            return super()._fill_text(text, width, indent)
        filled = super()._fill_text(head, width, indent) + "\n\n" if head.strip() else ""
        return filled + indent + "examples:\n" + "\n".join(
            indent + line for line in examples.splitlines())


__all__ = ["EXAMPLES", "ExamplesFormatter", "epilog"]
