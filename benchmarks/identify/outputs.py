"""What ``hexapod-bench identify`` writes: ``identified.toml``, ``identification.json``,
``report.md`` and ``residuals.png`` (through :func:`hexapod.outputs.write_output`)."""

from __future__ import annotations

import datetime
import io
import subprocess
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from benchmarks.identify.pipeline import Identification
from hexapod.dynamics.identification.estimation import moved_from_prior
from hexapod.dynamics.identification.parameters import STANDARD_NAMES, to_tables, unit
from hexapod.exceptions import IdentificationError, InertiaError
from hexapod.geometry import HexapodGeometry
from hexapod.outputs import PNG_METADATA, check_replace, write_output

#: The files ``identify`` writes into its folder.
OUTPUTS = ("identified.toml", "identification.json", "residuals.png", "report.md")


def identified_geometry(ident: Identification, source: str | None = None) -> HexapodGeometry:
    """The robot file with the identified ``[inertia]`` and ``[drives]`` tables."""
    inertia, drives = to_tables(ident.estimate.standard, ident.robot.inertia,
                                ident.robot.drives, source)
    return replace(ident.robot, inertia=inertia, drives=drives)


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=5, cwd=Path(__file__).parent)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def document(ident: Identification, command: str) -> dict[str, Any]:
    """The ``identification.json`` content."""
    est, basis = ident.estimate, ident.basis
    true_base = basis.of(ident.truth) if ident.truth is not None else None
    params = []
    for i, name in enumerate(basis.names):
        k = int(basis.independent[i])
        row: dict[str, Any] = {"name": name, "unit": unit(STANDARD_NAMES[k]),
                               "estimate": float(est.theta[i]), "se": float(est.se[i]),
                               "prior": float(basis.of(ident.prior)[i])}
        if true_base is not None:
            row["true"] = float(true_base[i])
            row["z"] = float((est.theta[i] - true_base[i]) / est.se[i])
        params.append(row)
    used = int(ident.mask.sum())
    kept, moved = kept_and_moved(ident)
    return {
        "command": command, "commit": _commit(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "robot": ident.robot.source or ident.robot.name,
        "record": ident.record,
        "excitation": ident.excitation.to_dict(),
        "base_parameters": params,
        "unidentifiable": list(basis.unidentifiable),
        "not_separable_kept_at_prior": kept, "not_separable_moved": moved,
        "standard": {n: float(x) for n, x in zip(STANDARD_NAMES, est.standard, strict=True)},
        "condition_weighted": est.condition,
        "residual_sigma_legs_n": est.sigma_legs.tolist(),
        "relative_residual": est.relative_residual,
        "equations_used": used, "samples": int(ident.mask.shape[0]),
        "consistency": est.consistency,
        "timings_s": ident.timings,
    }


def toml_text(ident: Identification, command: str) -> str:
    """``identified.toml``: the robot file with the identified tables and its provenance."""
    geometry = identified_geometry(ident)
    basis = ident.basis
    lines = [f"# identified by: {command}",
             f"# commit {_commit()}, {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, "
             f"from {ident.robot.source or ident.robot.name}; details in identification.json",
             f"# base parameters identified: {basis.size}; condition number of the "
             f"excitation {ident.excitation.condition:.4g}",
             *_separation_lines(ident), ""]
    return "\n".join(lines) + tomli_w.dumps(geometry.to_dict(dynamics=True))


def kept_and_moved(ident: Identification) -> tuple[list[str], list[str]]:
    """The standard parameters the leg forces cannot separate: those kept at the robot
    file's values, and those the constrained fit moved to a physical split."""
    moved = moved_from_prior(ident.basis, ident.estimate.standard, ident.prior)
    return ([STANDARD_NAMES[int(j)] for j in ident.basis.dependent if int(j) not in moved],
            [STANDARD_NAMES[j] for j in moved])


def _separation_lines(ident: Identification) -> list[str]:
    """The header lines of ``identified.toml`` on the parameters not separable."""
    kept, moved = kept_and_moved(ident)
    lines = []
    if kept:
        lines.append("# kept at the robot file's values (the leg forces cannot separate "
                     "them): " + ", ".join(kept))
    if moved:
        lines.append("# not separable by the leg forces, moved from the robot file's values "
                     "to a physical split by the constrained fit: " + ", ".join(moved))
    return lines


def residual_png(ident: Identification) -> bytes:
    """The fit's residuals against time, one panel per leg, and measured vs model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s, est = ident.samples, ident.estimate
    fig, axes = plt.subplots(6, 1, figsize=(9, 10), sharex=True)
    model = s.forces - np.nan_to_num(est.residuals)
    for i, ax in enumerate(axes):
        m = ident.mask[:, i]
        ax.plot(s.time, s.forces[:, i], lw=0.6, color="0.6", label="measured (filtered)")
        ax.plot(s.time[m], model[m, i], ".", ms=1.5, color="C0", label="model")
        ax.plot(s.time[m], est.residuals[m, i] * 10, ".", ms=1.5, color="C3",
                label="residual x 10")
        ax.set_ylabel(f"leg {i} [N]")
    axes[0].legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"identification residuals: sigma per leg "
                 f"{np.round(est.sigma_legs, 3).tolist()} N")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80, metadata=PNG_METADATA)  # one Software chunk
    plt.close(fig)
    return buf.getvalue()


def report_text(doc: dict[str, Any]) -> str:
    """``report.md``."""
    lines = ["# Dynamic identification", "", f"`{doc['command']}` (commit {doc['commit']}, "
             f"{doc['date']})", "",
             f"Robot: {doc['robot']}; record: {doc['record']}.", "",
             f"Excitation: Fourier series, {doc['excitation']['harmonics']} harmonics of "
             f"{doc['excitation']['base_frequency_hz']} Hz, condition number of the scaled "
             f"base regressor {doc['excitation']['condition']:.4g}; limits used "
             f"{ {k: round(v, 4) for k, v in doc['excitation']['limits'].items()} }.", "",
             f"Estimation: {doc['equations_used']} leg equations of {doc['samples']} samples, "
             f"weighted least squares (condition {doc['condition_weighted']:.4g}), residual "
             f"sigma per leg {[round(x, 4) for x in doc['residual_sigma_legs_n']]} N, relative "
             f"residual {doc['relative_residual']:.4g}.", "",
             "Physical consistency: " + " ".join(
                 x if x.rstrip().endswith(".") else x.rstrip() + "." for x in doc["consistency"])
             + ("" if doc.get("identified_toml", "identified.toml") else
                f" No robot file written (identified.toml): "
                f"{doc['identified_toml_refused'].removeprefix('not written: ')}."), "",
             "| base parameter | unit | estimate | SE | prior (robot file) |"
             + (" true | z |" if "true" in doc["base_parameters"][0] else ""),
             "|---|---|---|---|---|" + ("---|---|" if "true" in doc["base_parameters"][0]
                                         else "")]
    for p in doc["base_parameters"]:
        row = (f"| {p['name']} | {p['unit']} | {p['estimate']:.6g} | {p['se']:.3g} | "
               f"{p['prior']:.6g} |")
        if "true" in p:
            row += f" {p['true']:.6g} | {p['z']:.2f} |"
        lines.append(row)
    lines += ["", "Not identifiable (they do not enter the dynamics): "
              + ", ".join(doc["unidentifiable"]) + ". Kept at the robot file's values "
              "(only their combinations above are identified): "
              + (", ".join(doc["not_separable_kept_at_prior"]) or "none") + "."
              + ("" if not doc["not_separable_moved"] else
                 " Not separable either, moved from the robot file's values to a physical "
                 "split by the constrained fit: " + ", ".join(doc["not_separable_moved"])
                 + "."), "",
              "![residuals](residuals.png)", "",
              f"Timings: { {k: round(v, 2) for k, v in doc['timings_s'].items()} }", ""]
    return "\n".join(lines)


def write_all(ident: Identification, out: Path, command: str, overwrite: bool) -> dict[str, Any]:
    """Write the four outputs into ``out``; returns the JSON document.

    An estimate that is still not physical after the constrained fit makes no robot file:
    ``identified.toml`` is not written (an older one of the project is removed), the
    others say why (``identified_toml`` in the JSON document, the report), and the
    caller reports it (:class:`~hexapod.exceptions.IdentificationError` after them).

    Raises:
        IdentificationError: ``identified.toml`` could not be made (the others written).
    """
    doc = document(ident, command)
    target = out / "identified.toml"
    text: str | None = None
    doc["identified_toml"] = None
    if not ident.estimate.converged:  # where the solver stopped is no estimate
        doc["identified_toml_refused"] = (
            "not written: the constrained solver did not converge (relative residual "
            f"{ident.estimate.relative_residual:.3g})")
    else:
        try:
            text = toml_text(ident, command)
            doc["identified_toml"] = "identified.toml"
        except InertiaError as exc:  # not physical: no robot file to give
            # the estimate's value, not the robot file's (its path is not named: it is fine)
            doc["identified_toml_refused"] = (f"not written: the estimate's {exc.field}: "
                                              f"{exc.problem}")
    if text is None:
        check_replace(target, overwrite)  # (a user's file is refused, not deleted)
        target.unlink(missing_ok=True)  # no robot file of an older run left beside
    else:
        write_output(target, text, overwrite)
    write_output(out / "identification.json", doc, overwrite)
    write_output(out / "residuals.png", residual_png(ident), overwrite)
    write_output(out / "report.md", report_text(doc), overwrite)
    if text is None:  # (the other three written first: they say what was estimated)
        why = doc["identified_toml_refused"].removeprefix("not written: ")
        raise IdentificationError(
            f"{target}: not written: " + (why if not ident.estimate.converged else
                                          "the estimate is not physical after the "
                                          f"constrained fit ({why})")
            + f"; {out}/report.md and identification.json say what was estimated")
    return doc
