"""The preflight's picture: the model's surface with the critical patches the slicer would fix.

Two views (from the front above, from below), each region in its own colour with its number,
the rest grey: a person sees at once whether the chosen patches are the ones meant (a flat
base, a rim) or scattered bits of an organic surface.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from core.tolerance import tol
from slicer.mesh_io import Surface

LEGEND_MAX = 8  # regions named in the legend (the command lists them all)
MAX_FACES = 30_000  # faces drawn at most, of the regions and of the rest (every k-th beyond)


def critical_patches_png(surface: Surface, face_region: np.ndarray, labels: list[str],
                         path: Path) -> Path:
    """Draw ``surface`` with its faces coloured by ``face_region`` ((F,) int, -1 none) and
    a legend of ``labels`` (one per region); write the PNG at ``path``."""
    v, f = surface.vertices, surface.faces
    keep = face_region >= 0
    rest, chosen = np.flatnonzero(~keep), np.flatnonzero(keep)
    if len(rest) > MAX_FACES:
        rest = rest[:: int(np.ceil(len(rest) / MAX_FACES))]
    if len(chosen) > MAX_FACES:
        chosen = chosen[:: int(np.ceil(len(chosen) / MAX_FACES))]
    shown = np.concatenate([rest, chosen])
    cmap = plt.get_cmap("tab10")
    colour = np.where(face_region[shown, None] >= 0,
                      np.array([cmap(int(k) % 10) for k in np.maximum(face_region[shown], 0)]),
                      np.array([0.78, 0.78, 0.78, 1.0]))
    # shade by the face normal so the shape reads
    tri = v[f[shown]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), tol.zero)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre, half = (lo + hi) / 2, float((hi - lo).max()) / 2
    fig = plt.figure(figsize=(10, 5), dpi=110)
    for k, (elev, azim, title) in enumerate(((25, -60, "from above"), (-25, -60, "from below"))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        light = np.array([np.cos(np.radians(azim)), np.sin(np.radians(azim)),
                          np.sign(elev) * 1.0])
        shade = 0.55 + 0.45 * np.abs(n @ (light / np.linalg.norm(light)))
        c = colour.copy()
        c[:, :3] *= shade[:, None]
        ax.add_collection3d(Poly3DCollection(tri, facecolors=c, edgecolors=c, linewidths=0.3,
                                             antialiased=False))
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_zlabel("z (mm)")
        ax.set_title(title)
    shown_labels = labels[:LEGEND_MAX]
    if len(labels) > LEGEND_MAX:
        shown_labels[-1] = f"... {len(labels) - LEGEND_MAX + 1} more (colours repeat)"
    handles = [plt.Rectangle((0, 0), 1, 1, color=cmap(k % 10))
               for k in range(len(shown_labels))]
    rows = int(np.ceil(len(handles) / 4))
    if handles:
        fig.legend(handles, shown_labels, loc="lower center", ncol=min(len(handles), 4),
                   fontsize=8)
    fig.suptitle(f"{surface.source.name}: critical regions ({len(labels)})")
    fig.tight_layout(rect=(0, 0.05 * rows + 0.02 if handles else 0, 1, 0.95))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
