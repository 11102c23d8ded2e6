"""Volume preservation (paper eqs. 1-3, 9, 11): match the deposited to the required volume.

The required volume of a layer component is the integral of the layer height over it,
``sum_f area_f * mean(H at f's corners)``. The deposited volume of a toolpath is
``sum over extruding segments of length * H * W`` with H and W at the segment midpoints
(mean of the two ends; eq. 2). The line spacing is ``tau * W_mean`` for both patterns
(contours: eq. 9; stripes: the frequency tau/W of eq. 11 written as a spacing W / tau', with
tau = 1 / tau'), so a larger tau means fewer lines and less volume. ``match_volume`` finds tau
by a safeguarded bisection: a bracket [lo, hi] with V(lo) > V_req > V(hi) is kept, the next
trial is the volume-ratio update tau * V / V_req (exact if V is proportional to 1 / tau) when
it falls inside the bracket, else the bracket's geometric midpoint. V(tau) is piecewise
continuous (a line and its connectors appear or vanish at some tau) and not strictly monotone,
so when the bisection ends inside a bracket with its best trial off by more than SCAN_ABOVE x
the tolerance, SCAN_POINTS more trials across it look for a tau within the tolerance (status
'converged-scan'); the best trial wins.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from slicer.slabs import height_integral
from slicer.status import VolumeStatus

T = TypeVar("T")

TAU_LIMITS = (0.5, 2.0)  # spacing factors outside this are not volume matching, they are bugs
SCAN_POINTS = 12  # extra trials across a bracket the bisection could not close
SCAN_MARGIN = 0.12  # the scan reaches this far (relative) beyond the bracket
SCAN_ABOVE = 3.0  # scan only when the best trial is off by more than this x the tolerance


def required_volume(
    vertices: NDArray[np.float64], faces: NDArray[np.int32], height: NDArray[np.float64]
) -> float:
    """Integral of the layer height over a layer (component), mm^3.

    Args:
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32.
        height: (n,) float64, mm, layer height per vertex.
    """
    one_layer = np.zeros(len(faces), dtype=np.int64)
    return float(height_integral(vertices, faces, one_layer, height, 1)[0])


def segment_volume(
    points: NDArray[np.float64],
    height: NDArray[np.float64],
    width: NDArray[np.float64],
    deposits: NDArray[np.bool_],
) -> NDArray[np.float64]:
    """Volume of each segment between consecutive waypoints, mm^3 (eq. 2).

    Args:
        points: (N, 3) float64, mm.
        height: (N,) float64, mm.
        width: (N,) float64, mm.
        deposits: (N - 1,) bool, segment i (points i -> i + 1) extrudes.

    Returns:
        (N - 1,) float64, zero where ``deposits`` is False.
    """
    if len(points) < 2:
        return np.zeros(0)
    length = np.linalg.norm(np.diff(points, axis=0), axis=1)
    h_mid = 0.5 * (height[1:] + height[:-1])
    w_mid = 0.5 * (width[1:] + width[:-1])
    return np.where(deposits, length * h_mid * w_mid, 0.0)


@dataclass(frozen=True)
class VolumeTrial:
    """One evaluation of the bisection.

    Attributes:
        tau: spacing factor tried.
        volume: mm^3, deposited volume with it.
        rel_error: volume / required - 1.
    """

    tau: float
    volume: float
    rel_error: float


@dataclass(frozen=True)
class VolumeMatch(Generic[T]):
    """Result of ``match_volume``.

    Attributes:
        tau: the chosen spacing factor (best trial).
        volume: mm^3, its deposited volume.
        required: mm^3.
        rel_error: volume / required - 1.
        status: 'converged' (|rel_error| < tolerance), 'stalled' (bracket narrower than the
            volume's jumps: the line count is discrete), 'max_iterations' or 'limit' (tau hit
            TAU_LIMITS).
        trace: every trial in order.
        result: the payload the evaluation returned for the chosen tau.
    """

    tau: float
    volume: float
    required: float
    rel_error: float
    status: str
    trace: tuple[VolumeTrial, ...]
    result: T = field(repr=False)


def match_volume(
    evaluate: Callable[[float], tuple[float, T]],
    required: float,
    tolerance: float,
    tau0: float = 1.0,
    max_iterations: int = 12,
) -> VolumeMatch[T]:
    """Find tau with |V(tau) / required - 1| < tolerance for a decreasing V(tau).

    Args:
        evaluate: tau -> (deposited volume mm^3, payload).
        required: mm^3, > 0.
        tolerance: relative volume error accepted.
        tau0: first trial.
        max_iterations: evaluations at most.
    """
    lo_t, hi_t = TAU_LIMITS
    trials: list[VolumeTrial] = []
    payloads: list[T] = []
    lo: float | None = None  # largest tau known to give too much volume
    hi: float | None = None  # smallest tau known to give too little
    tau = float(np.clip(tau0, lo_t, hi_t))
    status = VolumeStatus.MAX_ITERATIONS
    def trial(t: float) -> tuple[float, float]:
        """Evaluate tau = t, record it; (volume, relative error)."""
        volume, payload = evaluate(t)
        err = volume / required - 1.0 if required > 0 else 0.0
        trials.append(VolumeTrial(t, float(volume), float(err)))
        payloads.append(payload)
        return float(volume), float(err)

    for _ in range(max(1, max_iterations)):
        volume, err = trial(tau)
        if abs(err) < tolerance:
            status = VolumeStatus.CONVERGED
            break
        if err > 0:
            lo = tau if lo is None else max(lo, tau)
        else:
            hi = tau if hi is None else min(hi, tau)
        if volume <= 0:
            guess = 0.5 * tau
        else:
            guess = tau * (1.0 + err)  # V ~ 1 / tau  =>  tau_new = tau V / V_req
        if lo is not None and hi is not None:
            if hi <= lo * (1.0 + 1e-4):
                status = VolumeStatus.STALLED  # the discrete line count jumps across the target
                break
            if not lo < guess < hi:
                guess = float(np.sqrt(lo * hi))
        guess = float(np.clip(guess, lo_t, hi_t))
        if guess == tau:
            status = VolumeStatus.LIMIT
            break
        tau = guess
    best_err = min(abs(t.rel_error) for t in trials)
    if (status in (VolumeStatus.MAX_ITERATIONS, VolumeStatus.STALLED)
            and lo is not None and hi is not None and best_err > SCAN_ABOVE * tolerance):
        # V(tau) jumps where a line (and its connectors) appears or vanishes and is not
        # monotone between jumps: scan the bracket for a tau within the tolerance
        for tau in np.linspace(min(lo, hi) * (1.0 - SCAN_MARGIN),
                               max(lo, hi) * (1.0 + SCAN_MARGIN), SCAN_POINTS):
            _, err = trial(float(np.clip(tau, lo_t, hi_t)))
            if abs(err) < tolerance:
                status = VolumeStatus.CONVERGED_SCAN
                break
    best = int(np.argmin([abs(t.rel_error) for t in trials]))
    chosen = trials[best]
    return VolumeMatch(
        tau=chosen.tau,
        volume=chosen.volume,
        required=float(required),
        rel_error=chosen.rel_error,
        status=status,
        trace=tuple(trials),
        result=payloads[best],
    )
