"""Layers as PLY files, one per layer, coloured by layer height, for any mesh viewer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from matplotlib import colormaps

from core.artifacts import atomic_write_bytes
from core.stages import Layers
from core.tolerance import tol


def export_layers_ply(layers: Layers, out_dir: Path) -> list[Path]:
    """Write ``out_dir/layer_XXXX.ply`` per layer; vertex colour = H on one shared scale."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    h = layers.vertex_height
    lo, hi = (float(np.percentile(h, 1)), float(np.percentile(h, 99))) if len(h) else (0.0, 1.0)
    cmap = colormaps["viridis"]
    written = []
    for index in range(layers.layer_count):
        layer = layers.layer(index)
        if len(layer.faces) == 0:
            continue
        t = np.clip((layer.height - lo) / max(hi - lo, tol.zero), 0.0, 1.0)
        colours = (np.asarray(cmap(t)) * 255).astype(np.uint8)
        mesh = trimesh.Trimesh(layer.vertices, layer.faces, vertex_colors=colours, process=False)
        path = out_dir / f"layer_{index:04d}.ply"
        data = mesh.export(file_type="ply")
        atomic_write_bytes(path, data if isinstance(data, bytes) else str(data).encode())
        written.append(path)
    return written
