"""Write the bundled example models and their job files (deterministic).

The models stand in for the test cases of the paper (section 5.1, Table 1) at the paper's
sizes: a prosthetic socket, an aorta phantom, a soft pneumatic actuator, a two-part dome
membrane, plus a cube and a hemisphere for tests and the demo. Every model is a closed,
consistently oriented triangle surface in millimetres with its lowest point at z = 0.

The surfaces are kept coarse (a few thousand faces): the tet-mesh resolution comes from
fTetWild's target edge length, not from the input triangles.

Usage::

    python examples/make_examples.py [--out DIR]   # default: the directory of this script
"""

from __future__ import annotations

import argparse
import io
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh
from manifold3d import CrossSection, JoinType, Manifold, Mesh

HERE = Path(__file__).resolve().parent

# Job files: a subset of the keys of slicer/defaults.toml. Layer heights follow Table 1
# (model height / layer count); the critical selectors follow section 5.1.
JOBS: dict[str, str] = {
    "socket": """\
# Prosthetic socket (paper Figure 1, Table 1: 137 x 125 x 212 mm, 340 layers).
# The saddle-shaped rim is the critical surface: it is printed as one continuous layer.
# Edge length: the paper's tet count (255.8 k) for this fuller solid (1.2 mm: ~3.7 M tets).
[mesh]
edge_length_mm = 2.9

[slicing]
layer_height_mm = 0.62
critical = ["top:45"]
""",
    "aorta": """\
# Aorta phantom (paper Figure 8, Table 1: 90 x 24 x 200 mm, 300 layers).
# Critical: the two tube end faces, plus the downward-facing strips of the arch
# (underside with the plaque, lumen ceiling) that lie within 30 deg of -z.
# Edge length: the paper's tet count (115.5 k); 1.2 mm would give ~0.37 M tets.
[mesh]
edge_length_mm = 1.8

[slicing]
layer_height_mm = 0.65
critical = ["bottom:30"]
""",
    "actuator": """\
# Soft pneumatic actuator (paper Figure 7, Table 1: 40 x 40 x 200 mm, 400 layers).
# The planar (degenerate) case: top and bottom faces critical, g = z.
# Edge length: the paper's tet count (207.3 k); 1.2 mm would give ~1.5 M tets.
[mesh]
edge_length_mm = 2.3

[slicing]
layer_height_mm = 0.5
critical = ["bottom:10", "top:10"]
planar = true
""",
    "membrane": """\
# Two-part dome membrane, mannequin chest (paper Figure 9, Table 1: 82 x 100 x 28 mm,
# 24 layers).
# Critical: the surfaces facing up (dome top, plate rim, cavity floor; 35 deg keeps the
# dome top one patch) and those facing down (bottom face, cavity ceiling).
# Edge length: the paper's tet count (197.5 k); 1.2 mm would give ~0.55 M tets.
# Layer height: 0.62 mm, 27 layers, which keeps H within the extrusion profile's range (up to
# 1.67 mm against the profile's 1.65). Model height / 24 (the paper's count) = 1.15 mm gives 14
# here: the layers above the cavity follow the dome (a 3-9 mm shell) and their H reached 3 mm
# (virtual print surface error 0.42 mm); 0.70 mm gives 23-24 layers with H up to 1.9 mm, and
# where that thick dome layer is a contour layer its width error p90 reaches 13-20 % (surface
# error as planned 0.24-0.26 mm); 0.62 mm: 0.21-0.22 mm. The thin dome layers lean the nozzle
# 46-50 deg at the dome's edge, where the bundled cell's 260 mm tank walls stand in the way:
# this job is planned for the shallow tray of planner/cells/tray.toml (examples/cells.toml;
# mesp demo --example membrane uses it). There the arm slows down on the dome's stripe layers
# (85-87 % of the extruding steps within 5 % of their speed) and the cell scales the
# extruder's rate with it (README).
[mesh]
edge_length_mm = 1.7

[slicing]
layer_height_mm = 0.62
critical = ["bottom:30", "top:35"]
""",
    "cube": """\
# 20 mm cube: the smallest planar job (tests).
[mesh]
edge_length_mm = 2.0

[slicing]
layer_height_mm = 0.6
critical = ["bottom:10", "top:10"]
planar = true
""",
    "hemisphere": """\
# Hemisphere, radius 20 mm, flat face down: the demo job. With the flat bottom critical
# and a constant layer height the optimal field is g = z: its layers come out planar.
[mesh]
edge_length_mm = 2.0

[slicing]
layer_height_mm = 0.6
critical = ["bottom:10"]
""",
}

# Documented overall sizes (x, y, z) in mm; tests check the generated files against them.
SIZES_MM: dict[str, tuple[float, float, float]] = {
    "socket": (137.0, 125.0, 212.0),
    "aorta": (90.0, 24.0, 200.0),
    "actuator": (40.0, 40.0, 200.0),
    "membrane": (82.0, 100.0, 28.0),
    "cube": (20.0, 20.0, 20.0),
    "hemisphere": (40.0, 40.0, 20.0),
}


def _to_manifold(vertices: np.ndarray, faces: np.ndarray) -> Manifold:
    """A Manifold from a closed triangle surface (vertices (n,3) mm, faces (m,3))."""
    mesh = Mesh(
        vert_properties=np.ascontiguousarray(vertices, dtype=np.float32),
        tri_verts=np.ascontiguousarray(faces, dtype=np.uint32),
    )
    solid = Manifold(mesh)
    if solid.is_empty():
        raise RuntimeError(f"surface is not a closed manifold ({solid.status()})")
    return solid


def _to_trimesh(solid: Manifold) -> trimesh.Trimesh:
    mesh = solid.to_mesh()
    out = trimesh.Trimesh(
        vertices=np.asarray(mesh.vert_properties[:, :3], dtype=np.float64),
        faces=np.asarray(mesh.tri_verts, dtype=np.int64),
        process=True,
    )
    # Rest on the build plate.
    out.apply_translation([0.0, 0.0, -out.bounds[0, 2]])
    return out


def socket() -> trimesh.Trimesh:
    """Prosthetic-socket-like cup: tapered elliptical wall, rounded closed bottom, saddle rim.

    The wall (10 mm) is a revolved profile: a quarter-ellipse bottom up to z = 40 mm, then a
    straight taper from radius 50 to 65.5 mm. A warp makes it elliptical (137 x 125 mm) and
    lifts the rim into a saddle (+-10 mm about z = 202 mm, two high sides and two low ones).
    """
    wall, r_bottom, r_top, z_knee, z_rim, saddle = 10.0, 50.0, 65.5, 40.0, 202.0, 10.0
    phi = np.linspace(0.0, np.pi / 2.0, 13)
    outer = np.column_stack([r_bottom * np.sin(phi), z_knee * (1.0 - np.cos(phi))])
    inner = np.column_stack(
        [(r_bottom - wall) * np.sin(phi), wall + (z_knee - wall) * (1.0 - np.cos(phi))]
    )
    profile = np.vstack([outer, [[r_top, z_rim]], [[r_top - wall, z_rim]], inner[::-1]])
    # The outline runs counter-clockwise in the (r, z) plane, as CrossSection expects.
    solid = Manifold.revolve(CrossSection([profile]), circular_segments=96)
    sx, sy = 137.0 / (2.0 * r_top), 125.0 / (2.0 * r_top)

    def warp(p: np.ndarray) -> np.ndarray:
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        theta = np.arctan2(y, x)
        rim = z_rim + saddle * np.cos(2.0 * theta)
        # Stretch the straight part of the wall (above the knee) so its top follows the rim.
        above = z > z_knee
        z_new = np.where(above, z_knee + (z - z_knee) * (rim - z_knee) / (z_rim - z_knee), z)
        return np.column_stack([x * sx, y * sy, z_new])

    return _to_trimesh(solid.warp_batch(warp))


def _sweep_tube(centre: np.ndarray, normal: np.ndarray, radius: float, segments: int) -> Manifold:
    """A closed tube of circular section swept along a planar centre line (in the x-z plane).

    Args:
        centre: (K, 3) float, mm, centre-line points.
        normal: (K, 3) float, unit in-plane normals of the centre line (the binormal is +y).
        radius: mm.
        segments: points per ring.
    """
    k = len(centre)
    phi = 2.0 * np.pi * np.arange(segments) / segments
    binormal = np.array([0.0, 1.0, 0.0])
    rings = (
        centre[:, None, :]
        + radius * np.cos(phi)[None, :, None] * normal[:, None, :]
        + radius * np.sin(phi)[None, :, None] * binormal[None, None, :]
    ).reshape(-1, 3)
    vertices = np.vstack([rings, centre[0], centre[-1]])
    i = np.arange(k - 1)[:, None]
    j = np.arange(segments)[None, :]
    a = i * segments + j
    b = i * segments + (j + 1) % segments
    side = np.concatenate(
        [np.stack([a, b, b + segments], -1), np.stack([a, b + segments, a + segments], -1)]
    ).reshape(-1, 3)
    first, last = k * segments, k * segments + 1
    ring0 = np.arange(segments)
    ringk = (k - 1) * segments + ring0
    cap0 = np.column_stack([np.full(segments, first), np.roll(ring0, -1), ring0])
    capk = np.column_stack([np.full(segments, last), ringk, np.roll(ringk, -1)])
    faces = np.vstack([side, cap0, capk])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    if mesh.volume < 0:  # orientation depends on the centre line's turning sense
        faces = faces[:, ::-1]
    return _to_manifold(vertices, faces)


def _aorta_centre_line(
    ascend_from: float, arch_z: float, arch_r: float, descend_to: float, step: float
) -> tuple[np.ndarray, np.ndarray]:
    """Centre line and in-plane normals: up at x = -R, a half circle over the top, down at +R."""
    up_z = np.arange(ascend_from, arch_z, step)
    up = np.column_stack([np.full_like(up_z, -arch_r), np.zeros_like(up_z), up_z])
    up_n = np.tile([1.0, 0.0, 0.0], (len(up_z), 1))
    t = np.linspace(np.pi, 0.0, 31)
    arch = np.column_stack([arch_r * np.cos(t), np.zeros_like(t), arch_z + arch_r * np.sin(t)])
    arch_n = -np.column_stack([np.cos(t), np.zeros_like(t), np.sin(t)])
    down_z = np.arange(arch_z, descend_to, -step)[1:]
    down_z = np.append(down_z, descend_to) if down_z[-1] > descend_to else down_z
    down = np.column_stack([np.full_like(down_z, arch_r), np.zeros_like(down_z), down_z])
    down_n = np.tile([-1.0, 0.0, 0.0], (len(down_z), 1))
    return np.vstack([up, arch, down]), np.vstack([up_n, arch_n, down_n])


def aorta() -> trimesh.Trimesh:
    """Aorta-like arch: ascending tube, half-circle arch, descending tube, with a plaque.

    Outer radius 12 mm, wall 2.5 mm, arch centre-line radius 33 mm (90 x 24 x 200 mm).
    The plaque is a solid ellipsoid on the inner curvature of the arch, just past its top
    towards the descending part, reaching up to 6 mm into the lumen.
    """
    r_out, wall, arch_r, arch_z = 12.0, 2.5, 33.0, 155.0
    centre, normal = _aorta_centre_line(80.0, arch_z, arch_r, 0.0, 10.0)
    outer = _sweep_tube(centre, normal, r_out, 40)
    # The lumen runs 1 mm past both end faces so the difference opens them cleanly.
    tangent0 = centre[0] - centre[1]
    tangent1 = centre[-1] - centre[-2]
    lumen_line = np.vstack(
        [centre[0] + tangent0 / np.linalg.norm(tangent0), centre, centre[-1] + tangent1 / 8.0]
    )
    lumen_normal = np.vstack([normal[0], normal, normal[-1]])
    lumen = _sweep_tube(lumen_line, lumen_normal, r_out - wall, 40)
    # Plaque: ellipsoid centred on the inner wall, 40 deg past the arch top (descending side).
    angle = np.deg2rad(50.0)
    radial = np.array([np.cos(angle), 0.0, np.sin(angle)])
    tangent = np.array([np.sin(angle), 0.0, -np.cos(angle)])
    at = np.array([0.0, 0.0, arch_z]) + (arch_r - r_out + wall) * radial
    rot = np.column_stack([tangent, [0.0, 1.0, 0.0], radial])  # local axes -> world
    transform = np.column_stack([rot @ np.diag([16.0, 8.0, 6.0]), at])
    plaque = Manifold.sphere(1.0, 32).transform(transform) ^ outer
    return _to_trimesh((outer - lumen) + plaque)


def actuator() -> trimesh.Trimesh:
    """Soft bending actuator: 40 x 40 x 200 mm block with a closed chain of air chambers.

    Eight cylindrical chambers (radius 13 mm, 14 mm tall) joined by a 3 mm axial channel,
    shifted 3 mm towards +x so the -x side is a thicker, strain-limiting solid wall.
    """
    block = Manifold.cube((40.0, 40.0, 200.0), center=True).translate((0.0, 0.0, 100.0))
    cavity = Manifold.cylinder(168.0, 3.0, circular_segments=24).translate((3.0, 0.0, 12.0))
    for k in range(8):
        chamber = Manifold.cylinder(14.0, 13.0, circular_segments=64)
        cavity = cavity + chamber.translate((3.0, 0.0, 12.0 + 22.0 * k))
    return _to_trimesh(block - cavity)


def _bumps(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height factor of the chest-like dome: two broad bumps on a smooth ellipsoid."""
    lobe = lambda cx, cy: np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2.0 * 13.0**2))  # noqa: E731
    return 1.0 + 0.45 * (lobe(4.0, 19.0) + lobe(4.0, -19.0))


def membrane() -> trimesh.Trimesh:
    """Two-part dome membrane: a rounded 82 x 100 x 8 mm base plate, a chest-like dome on it
    (top at 28 mm) and a closed cavity between the plate and the dome membrane.

    The dome's outer surface carries two bumps, the cavity is a plain half ellipsoid, so the
    membrane thickness varies (about 3 mm away from the bumps, up to 9 mm under them).
    """
    plate_h, top = 8.0, 28.0
    outline = CrossSection.square((74.0, 92.0), center=True).offset(4.0, JoinType.Round, 2.0, 32)
    plate = Manifold.extrude(outline, plate_h)
    a, b, c = 36.0, 45.0, 12.0
    dome = Manifold.sphere(1.0, 96).scale((a, b, c)).trim_by_plane((0.0, 0.0, 1.0), 0.0)
    verts = np.asarray(dome.to_mesh().vert_properties[:, :3], dtype=np.float64)
    peak = float(np.max(verts[:, 2] * _bumps(verts[:, 0], verts[:, 1])))
    # The dome's base sinks 1 mm into the plate: no coplanar faces for the booleans.
    base = plate_h - 1.0
    gain = (top - base) / peak

    def warp(p: np.ndarray) -> np.ndarray:
        z = p[:, 2] * gain * _bumps(p[:, 0], p[:, 1]) + base
        return np.column_stack([p[:, 0], p[:, 1], z])

    dome = dome.warp_batch(warp)
    # Cavity (floor on the plate top): 3 mm inside the dome's footprint and 3 mm below its
    # un-bumped top, so the membrane is 3 mm thick where there is no bump.
    c_in = c * gain - 4.0
    cavity = (
        Manifold.sphere(1.0, 96)
        .scale((a - 3.0, b - 3.0, c_in))
        .trim_by_plane((0.0, 0.0, 1.0), 0.0)
        .translate((0.0, 0.0, plate_h))
    )
    return _to_trimesh((plate + dome) - cavity)


def cube() -> trimesh.Trimesh:
    """A 20 mm cube with one corner at the origin."""
    return _to_trimesh(Manifold.cube((20.0, 20.0, 20.0)))


def hemisphere() -> trimesh.Trimesh:
    """A hemisphere of radius 20 mm, flat face down on z = 0, centred on the z axis."""
    return _to_trimesh(Manifold.sphere(20.0, 64).trim_by_plane((0.0, 0.0, 1.0), 0.0))


MODELS: dict[str, Callable[[], trimesh.Trimesh]] = {
    "socket": socket,
    "aorta": aorta,
    "actuator": actuator,
    "membrane": membrane,
    "cube": cube,
    "hemisphere": hemisphere,
}


def stl_bytes(mesh: trimesh.Trimesh) -> bytes:
    """The mesh as binary STL (deterministic: fixed header, float32 coordinates)."""
    buffer = io.BytesIO()
    mesh.export(buffer, file_type="stl")
    return buffer.getvalue()


def write_all(out: Path) -> list[Path]:
    """Write every model (``NAME.stl``) and its job file (``NAME.toml``) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, build in MODELS.items():
        mesh = build()
        if not mesh.is_watertight or mesh.volume <= 0:
            raise RuntimeError(f"{name}: generated surface is not a closed positive solid")
        (out / f"{name}.stl").write_bytes(stl_bytes(mesh))
        (out / f"{name}.toml").write_text(JOBS[name])
        written += [out / f"{name}.stl", out / f"{name}.toml"]
        size = mesh.bounds[1] - mesh.bounds[0]
        print(
            f"{name:11s} {len(mesh.faces):6d} faces  volume {mesh.volume:10.0f} mm^3  "
            f"size {size[0]:.1f} x {size[1]:.1f} x {size[2]:.1f} mm"
        )
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=HERE, help="output directory")
    args = parser.parse_args()
    write_all(args.out)


if __name__ == "__main__":
    main()
