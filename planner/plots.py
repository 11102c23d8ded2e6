"""PNG figures of a plan: joint angles over time, alpha histogram, clearance along the path,
singularity margin and the nozzle's deviation from the layer normal."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.figure_style import legend_outside, style
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


def time_axis(t: np.ndarray) -> tuple[np.ndarray, str]:
    """Times ``t`` (s) in the unit a person reads best for the job's length, and its label."""
    end = float(t[-1]) if len(t) else 0.0
    if end > 5 * 3600:
        return t / 3600.0, "time (h)"
    if end > 20 * 60:
        return t / 60.0, "time (min)"
    return t, "time (s)"


def write_plan_figures(result: PlanResult, out_dir: Path) -> list[Path]:
    """Write plan_joints.png, plan_alpha.png, plan_clearance.png and plan_margin.png into
    ``out_dir``."""
    with style():
        return _write(result, out_dir)


def _write(result: PlanResult, out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    traj = result.trajectory
    sl = _every(len(traj))
    paths = []
    tt, t_label = time_axis(np.asarray(traj.t))
    names = ("base", "shoulder", "elbow", "wrist 1", "wrist 2", "wrist 3")

    fig, ax = plt.subplots(figsize=(9, 4))
    for j in range(6):
        ax.plot(tt[sl], np.degrees(traj.q[sl, j]), lw=0.8, label=f"q{j + 1} {names[j]}")
    ax.set_xlabel(t_label)
    ax.set_ylabel("joint angle (deg)")
    legend_outside(ax)
    ax.set_title(f"UR5e joint angles over the plan ({traj.duration_s / 60:.1f} min)")
    fig.tight_layout()
    paths.append(out_dir / "plan_joints.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7.5, 4))
    alpha = traj.alpha[traj.extrude]
    ax.hist(alpha, bins=list(np.arange(60.0, 121.0, 1.0)))
    ax.axvspan(70, 110, color="g", alpha=0.1, label="allowed")
    ax.set_xlabel("printing angle alpha (deg)")
    ax.set_ylabel("extruding trajectory samples")
    ax.set_title("printing angle while extruding (90 deg ideal)")
    legend_outside(ax)
    fig.tight_layout()
    paths.append(out_dir / "plan_alpha.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(9, 4))
    has = np.isfinite(result.clearance)
    if has.any():
        t_c, lo_c, hi_c = _envelope(tt[has], result.clearance[has])
        ax.fill_between(t_c, lo_c, hi_c, lw=0.0, step="post", alpha=0.3, label="clearance range")
        ax.plot(t_c, lo_c, lw=0.7, drawstyle="steps-post", label="clearance, min")
    ax.axhline(result.report["required_clearance_mm"], color="r", ls="--", label="required")
    ax.set_xlabel(t_label)
    ax.set_ylabel("clearance (mm)")
    legend_outside(ax)
    ax.set_title("smallest clearance of arm and tool to the cell")
    fig.tight_layout()
    paths.append(out_dir / "plan_clearance.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    # where the arm comes near a singularity, and how far the nozzle leaves the layer normal
    # (upright, tilt, lean) to keep it away
    fig, ax = plt.subplots(figsize=(9, 4.4))
    margin = kin.singularity_margin(traj.q)
    t_m, lo_m, hi_m = _envelope(tt, margin)
    ax.fill_between(t_m, lo_m, hi_m, lw=0.0, step="post", alpha=0.3, label="margin range")
    ax.plot(t_m, lo_m, lw=0.7, drawstyle="steps-post", label="singularity margin, min")
    ax.axhline(COMFORT, color="g", ls=":", label="upright below")
    ax.set_xlabel(t_label)
    ax.set_ylabel("singularity margin (0 = singular)")
    ax.set_ylim(0.0, max(1.0, float(margin.max())))
    ax2 = ax.twinx()
    ax2.grid(False)
    ex = np.flatnonzero(traj.extrude)
    top = 5.0
    if len(ex):
        axis = np.concatenate([kin.fk(traj.q[ex[i:i + 65536]], _tool_m(traj.tool_T))[:, :3, 2]
                               for i in range(0, len(ex), 65536)])
        dev = np.degrees(np.arccos(np.clip(
            -np.einsum("ij,ij->i", axis, result.samples.normal[ex]), -1.0, 1.0)))
        # arccos near 1 turns float noise into ~1e-6 deg: below 0.01 deg it is no deviation
        dev = np.where(dev < 0.01, 0.0, dev)
        t_d, _, hi_d = _envelope(tt[ex], dev)
        ax2.plot(t_d, hi_d, lw=0.8, color="C1", drawstyle="steps-post",
                 label="nozzle from -normal, max (deg)")
        top = max(top, 1.1 * float(dev.max()))
    ax2.set_ylim(0.0, top)
    ax2.set_ylabel("nozzle deviation from -normal (deg), extruding", color="C1")
    lines = ax.get_legend_handles_labels()
    more = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="upper center",
              bbox_to_anchor=(0.5, -0.15), ncol=2, borderaxespad=0.0)
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
