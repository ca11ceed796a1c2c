"""Replay of a recorded trial: a self-contained animated HTML page and the
matplotlib curves beside it."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np

from hexapod.exceptions import ViewerError
from hexapod.outputs import HTML_MARKER, PNG_METADATA, TEXT_MARKER, replace_whole
from hexapod.visualize.records import TrialRecord, load_trial
from hexapod.visualize.viewer import HexapodViewer

log = logging.getLogger(__name__)

# Put in the exported page right after the viewer is created. MeshCat's page applies its
# commands asynchronously (one fetch of a data: URL each) and lists the animation first,
# before the objects it animates exist; this holds the animation until every command is
# applied, then loads it, and ``page.html#t=1.5`` shows it paused at 1.5 s.
_PAGE_SCRIPT = """
(function () {
  var expected = %d, seen = 0, held = null;
  var m = /(?:^#|&)t=([0-9.eE+-]+)/.exec(window.location.hash);
  var seekTo = m === null ? null : parseFloat(m[1]);
  var load = viewer.set_animation.bind(viewer);
  var handle = viewer.handle_command_bytearray.bind(viewer);
  function finish() {
    if (held !== null) { load(held[0], held[1]); held = null; }
    if (seekTo !== null && viewer.animator) {
      viewer.animator.pause();
      viewer.animator.seek(seekTo);
      viewer.animator.display_progress(seekTo);
    }
    window.hexapodReplayReady = true;
  }
  viewer.set_animation = function (animations, options) {
    if (seen < expected) { held = [animations, options]; } else { load(animations, options); }
  };
  viewer.handle_command_bytearray = function (bytes) {
    handle(bytes);
    seen += 1;
    if (seen === expected) { finish(); }
  };
})();
"""
_VIEWER_CREATED = re.compile(r"var viewer = new MeshCat\.Viewer\([^;]*\);")


def _scene_for(record: TrialRecord) -> HexapodViewer:
    viewer = HexapodViewer(record.geometry)
    a = record.arrays
    viewer.show_camera(a["camera_from_base"], a["camera_K"], int(a["camera_size"][0]),
                       int(a["camera_size"][1]), record.camera_kind)
    viewer.show_goal(a["goal_rotation"], a["goal_translation"])
    return viewer


def replay_html(record: TrialRecord, html_path: str | Path, fps: float = 25.0,
                frame: int | None = None) -> Path:
    """Write a self-contained HTML page of a trial (no network needed to open it).

    The page plays the trial once at its own pace; ``page.html#t=1.5`` opens it
    paused at 1.5 s of the trial (the Animations panel replays and scrubs it).

    Args:
        record: The trial.
        html_path: Output file.
        fps: Frames per second of the animation.
        frame: If given, a still of that control period instead of the animation
            (negative values count from the end).

    Returns:
        The path written.
    """
    with _scene_for(record) as viewer:
        k = 0 if frame is None else frame % record.frames
        viewer.display(record["rotations"][k], record["translations"][k],
                       record["edge_visible"][k], force=True)
        if frame is None:
            viewer.animate(record, fps)
        html = viewer.static_html()
    import html as html_text

    html = html.replace("<title>MeshCat</title>",  # the page names its trial
                        f"<title>{html_text.escape(record.title)}</title>", 1)
    html = _with_marker(_with_page_script(html))
    path = replace_whole(html_path, html)  # (a full disk left a 0-byte page, refused next)
    log.info("%s: wrote %s (%.1f MB)", record.title, path, len(html) / 1e6)
    return path


def _with_marker(html: str) -> str:
    """The page with :data:`hexapod.outputs.HTML_MARKER` in its head (or at its top), so
    that a later ``viz --html`` may replace it."""
    head = html.find("<head>")
    if 0 <= head < 4096:
        return html[:head + 6] + HTML_MARKER + html[head + 6:]
    doctype = html.find(">") + 1 if html.lstrip().lower().startswith("<!doctype") else 0
    return html[:doctype] + f"\n<!-- {TEXT_MARKER} -->\n" + html[doctype:]


def _with_page_script(html: str) -> str:
    """The page with :data:`_PAGE_SCRIPT` run right after its viewer is created."""
    found = _VIEWER_CREATED.search(html)
    if found is None:
        raise ViewerError("unexpected static HTML from meshcat: no 'var viewer = new "
                          "MeshCat.Viewer(...)' to hook the animation to")
    script = _PAGE_SCRIPT % html.count("viewer.handle_command_bytearray(")
    return html[:found.end()] + script + html[found.end():]


def plot_trial(record: TrialRecord, png_path: str | Path) -> Path:
    """Plot the trial's curves: feature error norm (log), position and orientation error
    (log), leg lengths against their strokes, and in the dynamic world the drive forces
    against their limits.

    Args:
        record: The trial.
        png_path: Output image.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = record.arrays
    t = a["t"]
    forces = "leg_forces" in a
    fig, axes = plt.subplots(1, 4 if forces else 3, figsize=(17.5 if forces else 13, 3.6))
    err = np.asarray(a["error_norm"], float)
    ok = np.isfinite(err) & (err > 0)
    axes[0].semilogy(t[ok], err[ok])
    axes[0].set_title("feature error norm")
    axes[1].semilogy(t, np.maximum(a["position_error"] * 1e3, 1e-6), label="position [mm]")
    axes[1].semilogy(t, np.maximum(np.rad2deg(a["orientation_error"]), 1e-7),
                     label="orientation [deg]")
    axes[1].set_title("pose error (true pose vs true goal)")
    axes[1].legend(fontsize=8)
    for i in range(6):
        axes[2].plot(t, a["lengths"][:, i] * 1e3, label=f"leg {i}")
    for q in a["stroke"]:
        axes[2].axhline(q * 1e3, color="k", linestyle="--", linewidth=0.8)
    axes[2].set_title("leg lengths [mm] and strokes")
    axes[2].legend(fontsize=7, ncol=2)
    if forces:  # the dynamic world
        for i in range(6):
            axes[3].plot(t, a["leg_forces"][:, i], label=f"leg {i}")
        for f in (a["force_limit"].max(), -a["force_limit"].max()):
            axes[3].axhline(f, color="k", linestyle="--", linewidth=0.8)
        axes[3].set_title("drive forces [N] and limits")
        axes[3].legend(fontsize=7, ncol=2)
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(record.title)
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata=PNG_METADATA)
    plt.close(fig)
    return replace_whole(png_path, buf.getvalue())


def replay_trial(npz_path: str | Path, html_path: str | Path) -> tuple[Path, Path]:
    """Replay a recorded trial: the HTML animation and, beside it, the matplotlib curves.

    Args:
        npz_path: The trial record.
        html_path: Output page; the curves go to the same name with ``.png``.

    Returns:
        The HTML and PNG paths.
    """
    record = load_trial(npz_path)
    html = replay_html(record, html_path)
    png = plot_trial(record, Path(html_path).with_suffix(".png"))
    return html, png
