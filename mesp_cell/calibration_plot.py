"""Pictures of a calibration (PNG, matplotlib's Agg canvas, no global backend state)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mesp_cell.calibration import RateFit
from mesp_cell.morphology_fit import MorphologyFit


def _figure(size: tuple[float, float]):  # type: ignore[no-untyped-def]
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=110)
    FigureCanvasAgg(fig)
    return fig


def plot_rate(fit: RateFit, path: Path, title: str) -> Path:
    """Weighed mass vs run time, the fitted line and its 95 % band (C +- U95 in the title),
    and below it each run's residual in mg (what the consistency check looks at)."""
    fig = _figure((6.4, 5.2))
    ax, res = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    t = np.linspace(0.0, float(fit.seconds.max()) * 1.05, 100)
    g = fit.density / 1000.0
    band = fit.expanded(0.95) * g * t
    ax.fill_between(t, fit.mass_at(t) - band, fit.mass_at(t) + band, color="tab:blue",
                    alpha=0.2, label="95 % band of the slope")
    ax.plot(t, fit.mass_at(t), color="tab:blue",
            label=f"fit: C = {fit.C:.4g} mm$^3$/s, start-up volume {fit.v0:+.3g} mm$^3$")
    ax.plot(fit.seconds, fit.mass, "o", color="tab:red", label="weighed runs (net)")
    ax.set_ylabel("net mass (g)")
    ax.set_xlim(0.0, t[-1])
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{title}\nC = {fit.C:.4g} +- {fit.expanded(0.95):.2g} mm$^3$/s (95 %) at "
                 f"set-point {fit.setpoint:g} mm$^3$/s", fontsize=9)
    res.axhline(0.0, color="tab:blue", lw=1)
    res.plot(fit.seconds, fit.residual_g * 1000.0, "o", color="tab:red")
    res.set_ylabel("residual (mg)")
    res.set_xlabel("run time (s)")
    res.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_morphology(fit: MorphologyFit, speed: np.ndarray, width: np.ndarray,
                    height: np.ndarray, path: Path, title: str) -> Path:
    """Measured filament width and height vs speed (log-log) and the fitted power laws."""
    fig = _figure((6.4, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    v = np.geomspace(float(fit.speed[0]), float(fit.speed[-1]), 100)
    ax.loglog(speed, width, "o", color="tab:blue", label="measured width $w_f$")
    ax.loglog(v, fit.a_w * v**fit.b_w, color="tab:blue",
              label=f"$w_f$ = {fit.a_w:.3g} $v^{{{fit.b_w:.3f}}}$ (R$^2$ {fit.r2_w:.3f})")
    ax.loglog(speed, height, "s", color="tab:orange", label="measured height $h_f$")
    ax.loglog(v, fit.a_h * v**fit.b_h, color="tab:orange",
              label=f"$h_f$ = {fit.a_h:.3g} $v^{{{fit.b_h:.3f}}}$ (R$^2$ {fit.r2_h:.3f})")
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    ax.set_xticks(np.unique(speed))  # the measured speeds
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.yaxis.set_minor_formatter(ScalarFormatter())
    ax.set_xlabel("nozzle speed v (mm/s)")
    ax.set_ylabel("filament size (mm)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"{title}: {fit.samples} filaments", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path
