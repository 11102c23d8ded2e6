"""One look for every PNG the project writes, so each reads at a glance.

``style()`` is a matplotlib rc context: no offset tick labels (a constant 2.3594 reads as
2.3594, not "1e-5 + 2.3594"), legends and colour bars kept in the saved image
(``savefig.bbox = tight``), light grids. ``legend_outside`` puts a legend right of the axes,
off the data (``legend_below`` under it, where a second y axis takes the right).
``value_limits`` keeps a colour range of nearly constant values readable.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np

from core.tolerance import tol

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.legend import Legend

STYLE: dict[str, Any] = {
    "axes.formatter.useoffset": False,
    "axes.formatter.limits": (-4, 6),
    "axes.grid": True,
    "grid.alpha": 0.3,
    "legend.fontsize": 8,
    "legend.framealpha": 0.9,
    "savefig.bbox": "tight",
    "savefig.pad_inches": 0.1,
}


@contextmanager
def style() -> Iterator[None]:
    """The project's figure style for the figures made and saved inside the block."""
    import matplotlib

    rc: Any = STYLE  # matplotlib types the keys as a Literal of every rc name
    with matplotlib.rc_context(rc):
        yield


def legend_outside(ax: Axes, handles: Sequence[Any] | None = None,
                   labels: Sequence[str] | None = None) -> Legend:
    """A legend to the right of ``ax``, outside the data area."""
    kwargs: dict[str, Any] = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0),
                              "borderaxespad": 0.0}
    if handles is not None:
        return ax.legend(handles, labels if labels is not None else
                         [str(h.get_label()) for h in handles], **kwargs)
    return ax.legend(**kwargs)


def legend_below(ax: Axes, handles: Sequence[Any] | None = None) -> Legend:
    """A legend in one row under ``ax`` (for axes with a second y axis on the right)."""
    hs = handles if handles is not None else ax.get_legend_handles_labels()[0]
    return ax.legend(hs, [str(h.get_label()) for h in hs], loc="upper center",
                     bbox_to_anchor=(0.5, -0.18), ncol=max(1, len(hs)), borderaxespad=0.0)


def integer_ticks(ax: Axes) -> None:
    """Whole-number ticks on the x axis of ``ax`` (layers, iterations)."""
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def value_limits(values: np.ndarray, min_span: float) -> tuple[float, float]:
    """(lo, hi) of the finite ``values``, widened about their middle to at least ``min_span``.

    A colour bar over values that differ by 1e-6 would otherwise show noise as colours.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, max(min_span, tol.zero)
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
    return lo, hi
