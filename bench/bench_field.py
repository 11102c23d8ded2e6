"""Time the field computation (paper 4.1) and the layer extraction on a model; print the stats.

Usage:
    .venv/bin/python bench/bench_field.py MODEL EDGE_MM [SELECTOR ...] [--height MM]

    MODEL     an STL (tetrahedralised with slicer.tetrahedralize at EDGE_MM, cached in
              /tmp/mesp_bench_<name>_<EDGE>.npz since meshing is not what is timed here) or a
              tetmesh .npz (EDGE_MM is then ignored)
    SELECTOR  critical selectors (default: top:45)

Example: .venv/bin/python bench/bench_field.py examples/socket.stl 2.7   (206,817 tets;
2.5 mm gives 408,362 tets; fTetWild takes 10-15 min CPU for these)

Prints wall-clock and CPU seconds (the field code runs one thread, so on an idle machine wall
should be close to CPU; on a loaded one it is not), the peak RSS, and the initial/final
layer-height statistics.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np


def tet_mesh(model: Path, edge: float) -> tuple[np.ndarray, np.ndarray]:
    if model.suffix == ".npz":
        data = np.load(model)
        return data["vertices"], data["tets"]
    cache = Path(f"/tmp/mesp_bench_{model.stem}_{edge:g}.npz")
    if cache.exists():
        data = np.load(cache)
        return data["vertices"], data["tets"]
    from slicer.config import MeshConfig
    from slicer.mesh_io import load_surface
    from slicer.tetrahedralize import tetrahedralize

    mesh, _ = tetrahedralize(load_surface(model), MeshConfig(edge_length_mm=edge))
    np.savez(cache, vertices=mesh.vertices, tets=mesh.tets)
    return mesh.vertices, mesh.tets


def main() -> None:
    from core.stages import TetMesh
    from slicer.config import SlicingConfig
    from slicer.field import compute_field
    from slicer.layers import extract_layers

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=Path)
    parser.add_argument("edge", type=float)
    parser.add_argument("selectors", nargs="*", default=["top:45"])
    parser.add_argument("--height", type=float, default=0.6)
    parser.add_argument("--smoothness", type=float, default=1.0)
    args = parser.parse_args()

    v, t = tet_mesh(args.model, args.edge)
    mesh = TetMesh(v, t)
    cfg = SlicingConfig(layer_height_mm=args.height, critical=tuple(args.selectors),
                        smoothness_weight=args.smoothness)
    c0, t0 = time.process_time(), time.perf_counter()
    res = compute_field(mesh, cfg)
    c1, t1 = time.process_time(), time.perf_counter()
    out = extract_layers(mesh, res, cfg)
    c2, t2 = time.process_time(), time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"{args.model.name}: tets {len(t)} vertices {len(v)} selectors {cfg.critical}")
    print(f"regions {len(res.regions.regions)}: "
          + ", ".join(f"{r.selector}:{len(r.faces)}f:{'end' if r.sign > 0 else 'start'}"
                      for r in res.regions.regions))
    print(f"field  wall {t1 - t0:6.2f} s  cpu {c1 - c0:6.2f} s  status {res.status} "
          f"iterations {res.iterations}")
    print("       stages (wall s): "
          + " ".join(f"{k}={s:.2f}" for k, s in res.timings.items()))
    print(f"layers wall {t2 - t1:6.2f} s  cpu {c2 - c1:6.2f} s  count {out.layers.layer_count} "
          f"faces {len(out.layers.faces)} mean height {out.spacing.mean_height_mm:.4f} mm")
    print(f"peak RSS {peak:.2f} GB")
    hi, hf = res.height_initial, res.height
    print(f"initial std {hi.std:.4f} cv {hi.cv:.3f} p5 {hi.p5:.3f} p95 {hi.p95:.3f}")
    print(f"final   std {hf.std:.4f} cv {hf.cv:.3f} p5 {hf.p5:.3f} p95 {hf.p95:.3f}  "
          f"std ratio {hf.std / hi.std:.3f}")
    print("std per iteration " + " ".join(f"{s:.4f}" for s in res.trace.height_std))
    print("height check", out.height_check)
    print("critical", [(r["selector"], r["slot"], r["on_one_layer"]) for r in out.critical_report])
    print("notes", res.notes)


if __name__ == "__main__":
    main()
