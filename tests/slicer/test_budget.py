"""The layer budget: estimated from the model's size before any work, refused above the limit."""

from __future__ import annotations

import pytest

from core.errors import InputError
from slicer.budget import MAX_LAYERS, check_budget, layer_estimate
from slicer.config import JobConfig


def test_layers_are_the_diagonal_over_the_height() -> None:
    assert layer_estimate((30.0, 40.0, 0.0), 0.5) == 101  # diagonal 50 mm
    assert check_budget((20.0, 20.0, 20.0), JobConfig()) == layer_estimate((20.0,) * 3, 0.6)


def test_too_many_layers_are_refused_with_a_height_that_fits() -> None:
    job = JobConfig().with_overrides(slicing={"layer_height_mm": 0.05})
    with pytest.raises(InputError, match="layer_height_mm to at least") as info:
        check_budget((200.0, 200.0, 200.0), job)
    least = float(info.value.fix.split("at least ")[1].split(",")[0])
    # following the fix works: the height it names fits the limit
    assert check_budget((200.0,) * 3, job.with_overrides(slicing={"layer_height_mm": least})) \
        <= MAX_LAYERS
