"""Toolpath files: ``toolpath.npz`` (the stage) and per-layer text files.

``DIR/layers_txt/layer_XXXX.txt`` holds the extruding waypoints of one layer, one per row,
columns ``x y z nx ny nz W H v`` (mm, unit, mm, mm, mm/s), each continuous extrusion path
introduced by a comment line ``# path <id>``; travel moves are not written (they are the gaps
between paths). ``read_layer_txt`` reads a file back.
"""

from __future__ import annotations

import io
import itertools
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from core.artifacts import atomic_write_bytes
from core.errors import InputError
from core.stages import Toolpath

HEADER = "x y z nx ny nz W H v"
LAYER_FILE = "layer_{:04d}.txt"


def save_toolpath(toolpath: Toolpath, job_dir: Path) -> Path:
    """Write ``toolpath.npz`` into ``job_dir`` atomically; returns its path."""
    return toolpath.save(Path(job_dir))


def layer_text(toolpath: Toolpath, layer: int) -> str:
    """The text file content of one layer."""
    on = (toolpath.layer == layer) & toolpath.extrude
    idx = np.flatnonzero(on)
    buf = io.StringIO()
    buf.write(f"# layer {layer}; columns: {HEADER} (mm, unit normal, mm, mm, mm/s)\n")
    if idx.size:
        cols = np.column_stack([
            toolpath.position[idx], toolpath.normal[idx], toolpath.width[idx],
            toolpath.height[idx], toolpath.speed[idx],
        ])
        paths = toolpath.path[idx]
        cut = np.flatnonzero(np.r_[True, paths[1:] != paths[:-1]])
        bounds = np.r_[cut, len(idx)]
        for a, b in itertools.pairwise(bounds):
            buf.write(f"# path {int(paths[a])}\n")
            np.savetxt(buf, cols[a:b], fmt="%.6f")
    return buf.getvalue()


def export_layers_txt(toolpath: Toolpath, out_dir: Path) -> list[Path]:
    """Write one ``layer_XXXX.txt`` per layer into ``out_dir``; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for layer in np.unique(toolpath.layer):
        path = out_dir / LAYER_FILE.format(int(layer))
        atomic_write_bytes(path, layer_text(toolpath, int(layer)).encode())
        written.append(path)
    return written


class LayerText(NamedTuple):
    """One layer text file read back.

    position: (k, 3) float64, mm; normal: (k, 3) float64; width, height: (k,) float64, mm;
    speed: (k,) float64, mm/s; path: (k,) int32, the path id of each row.
    """

    position: NDArray[np.float64]
    normal: NDArray[np.float64]
    width: NDArray[np.float64]
    height: NDArray[np.float64]
    speed: NDArray[np.float64]
    path: NDArray[np.int32]


def read_layer_txt(path: Path) -> LayerText:
    """Read a file written by ``export_layers_txt``.

    Raises:
        InputError: the file is missing or a row does not have 9 numbers.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path} does not exist", "export the toolpath first")
    rows: list[list[float]] = []
    ids: list[int] = []
    current = -1
    for number, raw in enumerate(path.read_text().splitlines(), start=1):
        text = raw.strip()
        if not text:
            continue
        if text.startswith("#"):
            parts = text[1:].split()
            if len(parts) == 2 and parts[0] == "path":
                current = int(parts[1])
            continue
        values = text.split()
        if len(values) != 9:
            raise InputError(f"{path}:{number} has {len(values)} columns, expected 9",
                             f"columns are {HEADER}")
        try:
            rows.append([float(x) for x in values])
        except ValueError as exc:
            raise InputError(f"{path}:{number} is not numeric", f"columns are {HEADER}") from exc
        ids.append(current)
    data = np.array(rows, dtype=np.float64).reshape(-1, 9)
    return LayerText(data[:, 0:3], data[:, 3:6], data[:, 6], data[:, 7], data[:, 8],
                     np.array(ids, dtype=np.int32))
