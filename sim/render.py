"""Offscreen pictures of the twin, where an OpenGL backend exists.

``Scene`` draws the cell from the twin's MJCF with a light sky, a headlight and a camera that
frames the work (the part in the tank, with the tool above it), plus user geoms (the ink laid
so far, ``sim.video``). MuJoCo picks its GL backend from ``MUJOCO_GL`` when it is first
imported (``sim.gl.choose_gl`` sets it). Without a working backend ``open_scene`` and
``render_png`` return the reason instead of raising: a missing display is never a crash.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.twin import GL_PROBLEM, Twin, mujoco

SKY = ('<asset><texture name="sky" type="skybox" builtin="gradient" rgb1="0.95 0.96 0.98" '
       'rgb2="0.72 0.76 0.82" width="64" height="64"/></asset>')
HEADLIGHT = '<headlight ambient="0.35 0.35 0.35" diffuse="0.55 0.55 0.55" specular="0.1 0.1 0.1"/>'


@dataclass(frozen=True)
class RenderResult:
    """Outcome of a render request.

    Attributes:
        path: the PNG written, or None if rendering is unavailable here.
        message: empty on success, else the reason (and how to enable rendering).
    """

    path: Path | None
    message: str


def render_xml(twin: Twin, part: tuple[np.ndarray, np.ndarray] | None = None) -> str:
    """The twin's MJCF with a sky and a headlight added (the kinematics unchanged), and the
    part as a faint ghost: ``part`` = (vertices (V, 3) float64 m in the world, faces (F, 3))."""
    xml = twin.xml.replace("<visual>", "<visual>" + HEADLIGHT, 1)
    asset, ghost = SKY, ""
    if part is not None and len(part[1]):
        verts = " ".join(f"{v:.6g}" for v in np.asarray(part[0], float).ravel())
        faces = " ".join(str(int(i)) for i in np.asarray(part[1]).ravel())
        asset = SKY.replace("</asset>", f'<mesh name="part" vertex="{verts}" face="{faces}" '
                            'inertia="shell"/></asset>')
        ghost = ('\n    <geom name="part_ghost" type="mesh" mesh="part" contype="0" '
                 'conaffinity="0" group="2" rgba="0.95 0.95 0.9 0.18"/>')
    return xml.replace("<worldbody>", asset + "\n  <worldbody>" + ghost, 1)


class Scene:
    """An offscreen renderer of one twin with a fixed camera.

    Attributes:
        width, height: image size, px. camera: the MjvCamera in use (free camera).
    """

    def __init__(self, twin: Twin, width: int, height: int, max_geom: int = 10000,
                 fast: bool = False, part: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        self.twin = twin
        self.model = mujoco.MjModel.from_xml_string(render_xml(twin, part))
        if fast:  # coarser round geoms, for thousands of ink capsules in software GL
            self.model.vis.quality.numslices = 12
            self.model.vis.quality.numstacks = 3
        self.model.vis.global_.offwidth = max(width, self.model.vis.global_.offwidth)
        self.model.vis.global_.offheight = max(height, self.model.vis.global_.offheight)
        # see-through environment (tank walls, gel) fainter, so the part and the ink show
        faint = ((self.model.geom_bodyid == 0) & (self.model.geom_rgba[:, 3] < 1.0)
                 & (self.model.geom_group != 2))
        self.model.geom_rgba[faint, 3] *= 0.4
        self.data = mujoco.MjData(self.model)
        self.width, self.height = width, height
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # GLFW warns about a missing display first
            self.renderer = mujoco.Renderer(self.model, height=height, width=width,
                                            max_geom=max_geom)
        if fast:  # shadows and reflections cost 3-4x the frame time without a GPU
            self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        self.camera = mujoco.MjvCamera()
        self.frame_work(self.model.geom("tank_floor").pos + np.array([0.0, 0.0, 0.05]), 0.25)

    def frame_work(self, lookat_m: np.ndarray, extent_m: float, azimuth: float = 135.0,
                   elevation: float = -30.0) -> None:
        """Point the camera at ``lookat_m`` (3,) m (world) so ``extent_m`` fills the view."""
        self.camera.lookat[:] = lookat_m
        fovy = np.radians(float(self.model.vis.global_.fovy))
        self.camera.distance = max(0.25, 1.3 * extent_m / np.tan(0.5 * fovy))
        self.camera.azimuth = azimuth
        self.camera.elevation = elevation

    def draw(self, q: np.ndarray, extra: list[tuple[np.ndarray, np.ndarray, float,
                                                     np.ndarray]] | None = None) -> np.ndarray:
        """The image (height, width, 3) uint8 of the cell at ``q`` (6,) rad.

        ``extra``: capsules to add, each (p0 (3,) m, p1 (3,) m, radius m, rgba (4,)).
        """
        self.data.qpos[self.twin.qadr] = q
        mujoco.mj_kinematics(self.model, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        scene = self.renderer.scene
        for p0, p1, radius, rgba in extra or []:
            if scene.ngeom >= scene.maxgeom:
                break
            g = scene.geoms[scene.ngeom]
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3),
                                np.eye(3).ravel(), rgba.astype(np.float32))
            mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, radius, p0, p1)
            scene.ngeom += 1
        return self.renderer.render().copy()

    def close(self) -> None:
        self.renderer.close()


def open_scene(twin: Twin, width: int, height: int, max_geom: int = 10000,
               fast: bool = False, part: tuple[np.ndarray, np.ndarray] | None = None
               ) -> tuple[Scene | None, str]:
    """A Scene, or None and the reason rendering is unavailable here."""
    if GL_PROBLEM:
        return None, (f"offscreen rendering unavailable: {GL_PROBLEM}; install that backend "
                      "(libegl1 or libosmesa6)")
    try:
        return Scene(twin, width, height, max_geom, fast, part), ""
    except Exception as exc:  # any GL failure means "no rendering here", never a crash
        import os

        backend = os.environ.get("MUJOCO_GL", "unset")
        return None, (f"offscreen rendering unavailable (MUJOCO_GL={backend}: {exc}); install "
                      "libegl1 or libosmesa6, or set MUJOCO_GL=egl or osmesa before starting")


def render_png(twin: Twin, q: np.ndarray, path: Path, width: int = 640, height: int = 480,
               lookat_m: np.ndarray | None = None, extent_m: float = 0.25) -> RenderResult:
    """Render the cell at joint angles ``q`` (6,) rad to ``path`` (PNG), framing ``lookat_m``
    (3,) m in the world (default: the tank) with ``extent_m`` in view."""
    scene, why = open_scene(twin, width, height)
    if scene is None:
        return RenderResult(None, why)
    try:
        if lookat_m is not None:
            scene.frame_work(np.asarray(lookat_m, float), extent_m)
        pixels = scene.draw(np.asarray(q, float))
    except Exception as exc:
        return RenderResult(None, f"offscreen rendering failed ({exc})")
    finally:
        scene.close()
    import imageio.v3 as iio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, pixels)
    return RenderResult(path, "")
