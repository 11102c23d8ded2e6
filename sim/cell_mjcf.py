"""MJCF of the cell, generated from the same cell description the planner uses.

World frame = cell frame. The arm is a chain of bodies following the UR5e DH parameters
(body i = DH frame i-1 turned by q_i, so MuJoCo's qpos equals the DH joint angles); its links
are the planner's collision capsules. Each joint has a position actuator (kp) and a velocity
actuator (kv, fed with the trajectory's joint rates) so replay tracks without lag. The tool
(holder, extruder, nozzle) hangs on the flange with a ``tcp`` site at the nozzle tip; table,
tank floor and walls are boxes; the gel is a translucent, non-colliding box. Gravity is
compensated on the arm bodies, as the real controller does. Lengths in m (MuJoCo's unit).
"""

from __future__ import annotations

import numpy as np

from planner import kinematics as kin
from planner.cell import CellConfig
from planner.collision import cell_boxes, robot_capsules


def _f(v: np.ndarray | tuple[float, ...] | list[float]) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.ravel(v))


def _quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (3, 3)."""
    w = np.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2.0
    x = np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2.0
    y = np.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2.0
    z = np.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2.0
    x = np.copysign(x, R[2, 1] - R[1, 2])
    y = np.copysign(y, R[0, 2] - R[2, 0])
    z = np.copysign(z, R[1, 0] - R[0, 1])
    q = np.array([w, x, y, z])
    return q / np.linalg.norm(q)


JOINT_NAMES = tuple(f"joint{i + 1}" for i in range(6))


def cell_mjcf(cell: CellConfig, kp: float = 100000.0, kv: float = 500.0,
              timestep: float = 0.001) -> str:
    """The MJCF XML text of ``cell`` (see module docstring)."""
    base_T = cell.robot.base_T.copy()
    base_T[:3, 3] /= 1000.0
    caps = robot_capsules(cell)
    lo = np.radians(cell.robot.joint_min_deg)
    hi = np.radians(cell.robot.joint_max_deg)
    vmax = np.radians(cell.robot.max_velocity_deg_s)

    env = []
    for box in cell_boxes(cell):
        centre = base_T[:3, :3] @ box.center + base_T[:3, 3]
        R = base_T[:3, :3] @ box.rotation
        if box.name == "gel":
            attrs = 'contype="0" conaffinity="0" rgba="0.6 0.8 1 0.25" group="1"'
        elif box.name in ("table", "pedestal"):
            attrs = 'rgba="0.55 0.45 0.35 1"'
        else:
            attrs = 'rgba="0.85 0.9 0.95 0.35"'
        env.append(
            f'    <geom name="{box.name}" type="box" pos="{_f(centre)}" quat="{_f(_quat(R))}" '
            f'size="{_f(box.half)}" {attrs}/>'
        )

    def capsule_geoms(body: int, indent: str) -> list[str]:
        out = []
        for c in caps:
            if c.body == body and not c.tool:
                out.append(
                    f'{indent}<geom name="{c.name}" type="capsule" fromto="{_f(c.p0)} {_f(c.p1)}"'
                    f' size="{c.radius:.6g}" rgba="0.7 0.72 0.75 1"/>'
                )
        return out

    lines: list[str] = []
    indent = "    "
    lines.append(f'{indent}<body name="base" pos="{_f(base_T[:3, 3])}" '
                 f'quat="{_f(_quat(base_T[:3, :3]))}">')
    lines.append(f'{indent}  <geom name="base_plate" type="cylinder" size="0.075 0.01" '
                 'pos="0 0 0.01" rgba="0.3 0.3 0.3 1"/>')
    depth = 1
    for i in range(6):
        ind = indent + "  " * depth
        if i == 0:
            pos, quat = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        else:
            pos = np.array([kin.A[i - 1], 0.0, kin.D[i - 1]])
            a = kin.ALPHA[i - 1]
            quat = np.array([np.cos(a / 2), np.sin(a / 2), 0.0, 0.0])
        lines.append(f'{ind}<body name="link{i + 1}" pos="{_f(pos)}" quat="{_f(quat)}" '
                     'gravcomp="1">')
        lines.append(f'{ind}  <joint name="{JOINT_NAMES[i]}" type="hinge" axis="0 0 1" '
                     f'range="{lo[i]:.9g} {hi[i]:.9g}" armature="0.1" damping="1"/>')
        lines.extend(capsule_geoms(i + 1, ind + "  "))
        depth += 1
    ind = indent + "  " * depth
    # flange = DH frame 6: offset d6 from the last body (alpha6 = 0)
    lines.append(f'{ind}<body name="flange" pos="0 0 {kin.D[5]:.9g}" gravcomp="1">')
    lines.append(f'{ind}  <site name="flange" size="0.005"/>')
    for c in caps:
        if not c.tool or c.name == "nozzle":
            continue
        part = next(p for p in cell.tool.parts if p.name == c.name)
        centre = np.asarray(part.center_mm) / 1000.0
        size = np.asarray(part.size_mm) / 1000.0
        if part.shape == "box":
            lines.append(f'{ind}  <geom name="{c.name}" type="box" pos="{_f(centre)}" '
                         f'size="{_f(size / 2)}" density="300" rgba="0.2 0.4 0.8 1"/>')
        else:
            lines.append(f'{ind}  <geom name="{c.name}" type="cylinder" pos="{_f(centre)}" '
                         f'size="{size[0] / 2:.6g} {size[2] / 2:.6g}" density="300" '
                         'rgba="0.2 0.4 0.8 1"/>')
    nozzle = next(c for c in caps if c.name == "nozzle")
    lines.append(f'{ind}  <geom name="nozzle" type="cylinder" fromto="{_f(nozzle.p0)} '
                 f'{_f(nozzle.p1)}" size="{nozzle.radius:.6g}" density="300" '
                 'rgba="0.8 0.8 0.2 1"/>')
    tool_T = cell.tool.tool_T
    lines.append(f'{ind}  <site name="tcp" pos="{_f(tool_T[:3, 3] / 1000.0)}" '
                 f'quat="{_f(_quat(tool_T[:3, :3]))}" size="0.003" rgba="1 0 0 1"/>')
    lines.append(f"{ind}</body>")
    for d in range(depth - 1, -1, -1):
        lines.append(indent + "  " * d + "</body>")

    actuators = []
    for i, name in enumerate(JOINT_NAMES):
        actuators.append(f'    <position name="p_{name}" joint="{name}" kp="{kp:.9g}" '
                         f'ctrlrange="{lo[i]:.9g} {hi[i]:.9g}"/>')
    for i, name in enumerate(JOINT_NAMES):
        actuators.append(f'    <velocity name="v_{name}" joint="{name}" kv="{kv:.9g}" '
                         f'ctrlrange="{-vmax[i]:.9g} {vmax[i]:.9g}"/>')

    return "\n".join(
        [
            '<mujoco model="mesp_cell">',
            '  <compiler angle="radian" autolimits="true"/>',
            f'  <option timestep="{timestep:.9g}" integrator="implicitfast"/>',
            '  <default><geom contype="0" conaffinity="0"/></default>',
            '  <visual><global offwidth="1280" offheight="960"/></visual>',
            "  <worldbody>",
            '    <light pos="0.4 0 2" dir="0 0 -1" directional="true"/>',
            *env,
            *lines,
            "  </worldbody>",
            "  <actuator>",
            *actuators,
            "  </actuator>",
            "</mujoco>",
            "",
        ]
    )
