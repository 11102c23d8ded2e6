"""PNG figures of a plan: joint angles over time, alpha histogram, clearance along the path."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planner.plan import PlanResult

MAX_POINTS = 20000  # plotted samples per curve; longer jobs are decimated evenly


def _every(n: int) -> slice:
    return slice(None, None, max(1, n // MAX_POINTS))


def write_plan_figures(result: PlanResult, out_dir: Path) -> list[Path]:
    """Write plan_joints.png, plan_alpha.png and plan_clearance.png into ``out_dir``."""
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
    ax.plot(traj.t[has][_every(int(has.sum()))], result.clearance[has][_every(int(has.sum()))],
            lw=0.8)
    ax.axhline(result.report["required_clearance_mm"], color="r", ls="--", label="required")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("clearance (mm)")
    ax.legend()
    ax.set_title("smallest clearance of arm and tool to the cell")
    fig.tight_layout()
    paths.append(out_dir / "plan_clearance.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)
    return paths
