"""The layers a slicing job asks for, estimated from the model before any work is done.

A job whose numbers are each within range can still ask for hours of work: 0.05 mm layers on
a 200 mm part are up to 7,000 layers, each a toolpath of its own.
``check_budget`` refuses such a job with one line before tetrahedralisation, naming the
estimate, the limit and the setting to change. (The tets fTetWild would make are estimated
and limited in ``slicer.tetrahedralize``.)
"""

from __future__ import annotations

import math

from core.errors import InputError
from slicer.config import JobConfig

#: Layers at most: each layer is a toolpath of its own.
MAX_LAYERS = 2000


def layer_estimate(bbox_mm: tuple[float, float, float], layer_height_mm: float) -> int:
    """Layers at most: the bounding-box diagonal (mm) over the layer height (curved layers
    may run along any direction; none is longer than the diagonal)."""
    return int(math.sqrt(sum(s * s for s in bbox_mm)) / layer_height_mm) + 1


def check_budget(bbox_mm: tuple[float, float, float], job: JobConfig) -> int:
    """The estimated layers, or an ``InputError`` if they exceed ``MAX_LAYERS``."""
    height = job.slicing.layer_height_mm
    layers = layer_estimate(bbox_mm, height)
    if layers > MAX_LAYERS:
        least = math.ceil(height * layers / MAX_LAYERS * 100) / 100
        raise InputError(f"the model could need up to {layers:,} layers at {height:g} mm, more "
                         f"than the limit {MAX_LAYERS:,}",
                         f"set [slicing] layer_height_mm to at least {least:g}, or check --units")
    return layers
