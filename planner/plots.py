"""PNG figures of a plan: joint angles over time, alpha histogram, clearance along the path,
singularity margin and the nozzle's deviation from the layer normal."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planner import kinematics as kin
from planner.plan import PlanResult
from planner.upright import COMFORT

MAX_POINTS = 20000  # plotted samples per curve; longer jobs are decimated evenly


def _every(n: int) -> slice:
    return slice(None, None, max(1, n // MAX_POINTS))


def _envelope(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, min, max) of ``y`` over consecutive bins of at most MAX_POINTS bins: a long job
    plotted without losing its extremes (evenly decimated, a curve hides its minima)."""
    starts = np.arange(0, len(y), max(1, len(y) // MAX_POINTS))
    return t[starts], np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts)


def write_plan_figures(result: PlanResult, out_dir: Path) -> list[Path]:
    """Write plan_joints.png, plan_alpha.png, plan_clearance.png and plan_margin.png into
    ``out_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    traj = result.trajectory
    sl = _every(len(traj))
    paths = []

    fig, ax = plt.subplots(figsize=(8, 4))
    for j in range(6):
        ax.plot(traj.t[sl], np.degrees(traj.q[sl, j]), label=f"q{j + 1}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("joint angle (deg)")
    ax.legend(ncol=6, fontsize=8)
    ax.set_title("UR5e joint angles")
    fig.tight_layout()
    paths.append(out_dir / "plan_joints.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    alpha = traj.alpha[traj.extrude]
    ax.hist(alpha, bins=list(np.arange(60.0, 121.0, 1.0)))
    ax.axvspan(70, 110, color="g", alpha=0.1, label="allowed")
    ax.set_xlabel("printing angle alpha (deg)")
    ax.set_ylabel("extruding samples")
    ax.legend()
    fig.tight_layout()
    paths.append(out_dir / "plan_alpha.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 4))
    has = np.isfinite(result.clearance)
    if has.any():
        t_c, lo_c, hi_c = _envelope(traj.t[has], result.clearance[has])
        ax.fill_between(t_c, lo_c, hi_c, lw=0.0, step="post", alpha=0.3, label="clearance range")
        ax.plot(t_c, lo_c, lw=0.7, drawstyle="steps-post", label="clearance, min")
    ax.axhline(result.report["required_clearance_mm"], color="r", ls="--", label="required")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("clearance (mm)")
    ax.legend()
    ax.set_title("smallest clearance of arm and tool to the cell")
    fig.tight_layout()
    paths.append(out_dir / "plan_clearance.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    # where the arm comes near a singularity, and how far the nozzle leaves the layer normal
    # (upright, tilt, lean) to keep it away
    fig, ax = plt.subplots(figsize=(8, 4))
    margin = kin.singularity_margin(traj.q)
    t_m, lo_m, hi_m = _envelope(traj.t, margin)
    ax.fill_between(t_m, lo_m, hi_m, lw=0.0, step="post", alpha=0.3, label="margin range")
    ax.plot(t_m, lo_m, lw=0.7, drawstyle="steps-post", label="singularity margin, min")
    ax.axhline(COMFORT, color="g", ls=":", label="upright below")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("singularity margin (0 singular)")
    ax.set_ylim(0.0, max(1.0, float(margin.max())))
    ax2 = ax.twinx()
    ex = np.flatnonzero(traj.extrude)
    if len(ex):
        axis = np.concatenate([kin.fk(traj.q[ex[i:i + 65536]], _tool_m(traj.tool_T))[:, :3, 2]
                               for i in range(0, len(ex), 65536)])
        dev = np.degrees(np.arccos(np.clip(
            -np.einsum("ij,ij->i", axis, result.samples.normal[ex]), -1.0, 1.0)))
        t_d, _, hi_d = _envelope(traj.t[ex], dev)
        ax2.plot(t_d, hi_d, lw=0.8, color="C1", drawstyle="steps-post",
                 label="nozzle from -normal, max (deg)")
    ax2.set_ylabel("nozzle deviation from -normal (deg), extruding")
    lines = ax.get_legend_handles_labels()
    more = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, loc="lower left")
    ax.set_title("arm away from singularities; nozzle off the layer normal")
    fig.tight_layout()
    paths.append(out_dir / "plan_margin.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)
    return paths


def _tool_m(tool_T: np.ndarray) -> np.ndarray:
    """Tool transform (4, 4) with its translation in m (``tool_T`` in mm), as FK expects."""
    m = np.array(tool_T, dtype=float)
    m[:3, 3] /= 1000.0
    return m
