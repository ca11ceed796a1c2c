"""MeshCat scene of the hexapod: live view, replay of a recorded trial, static HTML export.

The scene is the closed-chain Pinocchio model (:mod:`hexapod.model`) drawn by
:class:`pinocchio.visualize.MeshcatVisualizer`: base, platform and the six legs
as cylinders of the true radius, plus the camera as a frustum (a mirror and a
wide cone for an omnidirectional camera) at its pose, the goal pose as a
translucent ghost platform, optionally the interpretation planes of the leg
edges, and leg colours that mark the legs whose edges the camera does not see
(occluded or outside the image).

Nothing here waits for a browser, and nothing waits for the MeshCat server
without a timeout:

- the server is started in a child process whose web server listens on
  127.0.0.1 only (``meshcat-server`` itself listens on every interface), and
  every ZeroMQ request to it times out (:data:`ZMQ_TIMEOUT`);
- :meth:`HexapodViewer.display` only hands the newest pose to a sender thread,
  which draws at most :data:`LIVE_PERIOD`-spaced updates: a control loop pays
  microseconds per call, watched or not;
- the HTML export asks the server for the scene (``static_html``), never for a
  screenshot.

A trial record is the ``.npz`` file the benchmark writes for a recorded trial
(see :data:`RECORD_SHAPES` and :func:`load_trial`). ``hexapod`` knows nothing of
cameras or controllers: records and camera drawings take plain arrays.

The package has one module per job: :mod:`~hexapod.visualize.records` (trial
records), :mod:`~hexapod.visualize.drawings` (the camera and edge-plane geometry),
:mod:`~hexapod.visualize.server` (the MeshCat server process),
:mod:`~hexapod.visualize.viewer` (the live view) and :mod:`~hexapod.visualize.replay`
(HTML export and curves).
"""

from typing import TYPE_CHECKING

from hexapod.exceptions import RecordError, ViewerError
from hexapod.lazy import lazy_names
from hexapod.visualize.records import (
    CAMERA_KINDS,
    RECORD_KEYS,
    RECORD_SHAPES,
    TrialRecord,
    load_trial,
    save_trial,
    synthetic_record,
)
from hexapod.visualize.server import SERVER_START_TIMEOUT, ZMQ_TIMEOUT

if TYPE_CHECKING:  # the viewer's names load on first use (module __getattr__ below)
    from hexapod.visualize.replay import plot_trial, replay_html, replay_trial
    from hexapod.visualize.viewer import LIVE_PERIOD, HexapodViewer

#: The names of the viewer and the replay, by module: they import the Pinocchio model
#: (0.15 s), which writing or reading a trial record does not need.
_LAZY = {"plot_trial": "replay", "replay_html": "replay", "replay_trial": "replay",
         "LIVE_PERIOD": "viewer", "HexapodViewer": "viewer"}


__getattr__ = lazy_names(__name__, {name: f"hexapod.visualize.{module}"
                                    for name, module in _LAZY.items()}, globals())


__all__ = [
    "CAMERA_KINDS", "LIVE_PERIOD", "RECORD_KEYS", "RECORD_SHAPES", "SERVER_START_TIMEOUT",
    "ZMQ_TIMEOUT", "HexapodViewer", "RecordError", "TrialRecord", "ViewerError",
    "load_trial", "plot_trial", "replay_html", "replay_trial", "save_trial",
    "synthetic_record",
]
