"""Calibration observations: edge normals and leg lengths over N configurations, and their
files (JSON or NPZ, lengths in millimetres).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import ConfigFileError, ShapeError

log = logging.getLogger(__name__)

#: Tolerance on the norm of the normals read from a file.
UNIT_TOLERANCE = 1e-6

FILE_FORMAT = "hexapod-leg-edge-observations"


@dataclass(frozen=True)
class CalibrationData:
    """Leg-edge observations over N robot configurations (all in the camera frame).

    Attributes:
        normals: (N, 6, 2, 3) unit edge normals (convention of :func:`vision.legs.leg_edges`);
            any value (e.g. NaN) where the edge is not visible.
        edge_visible: (N, 6, 2) whether each edge was observed.
        lengths: (N, 6) measured leg lengths [m] (not used by the linear system; kept
            with the images they go with).
        source: File the data were read from, if any.
    """

    normals: np.ndarray
    edge_visible: np.ndarray
    lengths: np.ndarray
    source: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        n = np.asarray(self.normals, dtype=float)
        if n.ndim != 4 or n.shape[1:] != (6, 2, 3):
            raise ShapeError("normals", "shape (N, 6, 2, 3)", n.shape)
        vis = np.asarray(self.edge_visible, dtype=bool)
        if vis.shape != n.shape[:3]:
            raise ShapeError("edge_visible", f"shape {n.shape[:3]}", vis.shape)
        q = np.asarray(self.lengths, dtype=float)
        if q.shape != n.shape[:2]:
            raise ShapeError("lengths", f"shape {n.shape[:2]}", q.shape)
        vis = vis & np.all(np.isfinite(n), axis=-1)
        object.__setattr__(self, "normals", n)
        object.__setattr__(self, "edge_visible", vis)
        object.__setattr__(self, "lengths", q)

    @property
    def n_configurations(self) -> int:
        """Number of configurations N."""
        return int(self.normals.shape[0])

    def take(self, indices: Sequence[int] | np.ndarray) -> CalibrationData:
        """The observations of some configurations (in the given order)."""
        idx = np.asarray(indices, dtype=int)
        return CalibrationData(self.normals[idx], self.edge_visible[idx], self.lengths[idx],
                               self.source)

    # --------------------------------------------------------------- files
    def to_dict(self) -> dict[str, Any]:
        """JSON-able file representation (hidden edges as ``null``, lengths in mm)."""
        normals: list[Any] = np.where(self.edge_visible[..., None], self.normals,
                                      np.nan).tolist()
        normals = _nan_to_none(normals)
        return {
            "format": FILE_FORMAT,
            "version": 1,
            "normals": normals,
            "edge_visible": self.edge_visible.tolist(),
            "lengths_mm": (self.lengths * 1e3).tolist(),
        }

    def save(self, path: str | Path) -> None:
        """Save to ``.json`` or ``.npz`` (by the suffix), lengths in millimetres."""
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".json":
            p.write_text(json.dumps(self.to_dict()))
        elif suffix == ".npz":
            np.savez(p, normals=self.normals, edge_visible=self.edge_visible,
                     lengths_mm=self.lengths * 1e3)
        else:
            raise ConfigFileError(str(p), "unknown file type; use .json or .npz")

    @classmethod
    def from_dict(cls, table: Mapping[str, Any], path: str = "<dict>") -> CalibrationData:
        """Build from the file representation.

        Keys: ``normals`` (N x 6 x 2 x 3, ``null`` (or three) for a hidden edge), ``lengths_mm``
        (N x 6) and optionally ``edge_visible`` (N x 6 x 2 booleans; default: the
        edges whose normal is given), ``format`` and ``version``.

        Raises:
            ConfigFileError: Missing, misspelt or malformed field (named in the message).
        """
        from hexapod.config import check_keys

        check_keys(table, ("format", "version", "normals", "edge_visible", "lengths_mm"), path,
                   required=("normals", "lengths_mm"))
        if "format" in table and table["format"] != FILE_FORMAT:
            raise ConfigFileError(path, f"expected '{FILE_FORMAT}', got {table['format']!r}",
                                  key="format")
        normals = _read_array(table, "normals", path, allow_none=True)
        if normals.ndim != 4 or normals.shape[1:] != (6, 2, 3) or normals.shape[0] == 0:
            raise ConfigFileError(path, f"expected shape (N, 6, 2, 3) with N >= 1, got "
                                  f"{normals.shape}", key="normals")
        lengths = _read_array(table, "lengths_mm", path) * 1e-3
        if lengths.shape != normals.shape[:2]:
            raise ConfigFileError(path, f"expected shape {normals.shape[:2]} (one length per "
                                  f"leg and configuration), got {lengths.shape}",
                                  key="lengths_mm")
        if not np.all(np.isfinite(lengths)):
            raise ConfigFileError(path, "contains NaN or inf", key="lengths_mm")
        given = np.all(np.isfinite(normals), axis=-1)
        partial = np.argwhere(np.any(np.isfinite(normals), axis=-1) & ~given)
        if len(partial):  # (it was taken for an edge not seen, without a word)
            k, i, j = partial[0]
            raise ConfigFileError(path, f"configuration {k} leg {i} edge {j}: normal "
                                  f"{_coordinates(normals[k, i, j])} lacks a coordinate (null, "
                                  "NaN or inf); an edge not seen is null, or three nulls",
                                  key="normals")
        if "edge_visible" in table:
            raw = table["edge_visible"]
            visible = np.asarray(raw)
            if visible.dtype != bool or visible.shape != normals.shape[:3]:
                raise ConfigFileError(path, f"expected booleans of shape {normals.shape[:3]}",
                                      key="edge_visible")
            missing = np.argwhere(visible & ~given)
            if len(missing):
                k, i, j = missing[0]
                raise ConfigFileError(path, f"configuration {k} leg {i} edge {j} is marked "
                                      "visible but has no finite normal", key="normals")
        else:
            visible = given
        norms = np.linalg.norm(np.where(visible[..., None], normals, 0.0), axis=-1)
        bad = np.argwhere(visible & (np.abs(norms - 1.0) > UNIT_TOLERANCE))
        if len(bad):
            k, i, j = bad[0]
            raise ConfigFileError(path, f"configuration {k} leg {i} edge {j}: normal of norm "
                                  f"{norms[k, i, j]:.9g}, expected a unit vector (within "
                                  f"{UNIT_TOLERANCE:g}: normalise them, or write them to 7 "
                                  "significant digits or more)", key="normals")
        return cls(normals, visible, lengths, source=path)

    @classmethod
    def load(cls, path: str | Path) -> CalibrationData:
        """Load observations from a ``.json`` or ``.npz`` file (see :meth:`from_dict`).

        Raises:
            ConfigFileError: Missing or unreadable file, unknown type, bad field.
        """
        p = Path(path)
        if not p.exists():
            raise ConfigFileError(str(p), "file not found")
        suffix = p.suffix.lower()
        if suffix == ".json":
            try:
                table = json.loads(p.read_text())
            except json.JSONDecodeError as exc:
                raise ConfigFileError(str(p), f"not valid JSON: {exc}") from None
            if not isinstance(table, dict):
                raise ConfigFileError(str(p), "expected a JSON object at the top level")
            return cls.from_dict(table, str(p))
        if suffix == ".npz":
            try:
                with np.load(p, allow_pickle=False) as npz:
                    table = {k: npz[k] for k in npz.files}
            except (OSError, ValueError) as exc:  # numpy's text for a file that is not a
                # zip of arrays suggests loading it with pickles: not repeated
                detail = ("not a zip of .npy arrays (a corrupt or other file)"
                          if "pickle" in str(exc) else str(exc))
                raise ConfigFileError(str(p), f"not a readable NPZ file: {detail}") from None
            if "edge_visible" in table:
                table["edge_visible"] = np.asarray(table["edge_visible"])
            return cls.from_dict(table, str(p))
        raise ConfigFileError(str(p), "unknown file type; use .json or .npz")


def _nan_to_none(x: Any) -> Any:
    if isinstance(x, list):
        return [_nan_to_none(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def _read_array(table: Mapping[str, Any], key: str, path: str,
                allow_none: bool = False) -> np.ndarray:
    value = table[key]
    if allow_none and isinstance(value, list):
        value = _none_to_nan(value, 3)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigFileError(path, "expected a regular nested array of numbers",
                              key=key) from None
    if not allow_none and not np.all(np.isfinite(arr)):
        at = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ConfigFileError(path, f"contains null, NaN or inf (at index {list(at)})",
                              key=key)
    return arr


def _coordinates(n: np.ndarray) -> str:
    """A normal's coordinates as a file shows them (``null`` for a missing one)."""
    return "[" + ", ".join("null" if not np.isfinite(v) else f"{v:g}" for v in n) + "]"


def _none_to_nan(x: Any, depth: int) -> Any:
    """Replace ``null`` by NaN; a ``null`` in place of a normal (``depth == 0``) stands
    for the three coordinates of a hidden edge."""
    if isinstance(x, list):
        return [_none_to_nan(v, depth - 1) for v in x]
    if x is None:
        return [np.nan] * 3 if depth == 0 else np.nan
    return x
