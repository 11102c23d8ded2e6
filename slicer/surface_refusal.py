"""Why a surface is refused: a reason enum the refusal carries, so repair dispatches on it.

``mesh_io.load_surface`` raises ``SurfaceRefused`` for a surface that is read but does not
bound a solid; its ``reason`` says which check failed (the member's ``message`` says what that
means), and ``slicer.repair`` picks the repair for it from the reason alone, never from the
wording of the one-line message. Problems with the file itself (missing, unreadable, of
absurd size) stay plain ``InputError``: no repair answers them.
"""

from __future__ import annotations

from core.errors import InputError
from core.status import Status


class SurfaceReason(Status):
    """The check of ``load_surface`` a surface failed."""

    OPEN = "open", ("edges used by one face: holes larger than a crack, or open sheets with "
                    "no inside")
    NON_MANIFOLD = "non-manifold", ("closed, but edges shared by 3 or more faces (bodies "
                                    "touching along an edge, an internal face)")
    NON_ORIENTABLE = "non-orientable", ("no consistent winding: a one-sided or "
                                        "self-overlapping surface")
    DEGENERATE = "degenerate", "every triangle has zero area"
    FLAT = "flat", "closed, but it encloses no volume (a flat or doubled-up surface)"


class SurfaceRefused(InputError):
    """``load_surface``'s refusal of a surface that does not bound a solid.

    Attributes:
        reason: which check failed.
    """

    def __init__(self, problem: str, fix: str, reason: SurfaceReason) -> None:
        super().__init__(problem, fix)
        self.reason = reason


class RepairRefused(InputError):
    """``--repair``'s refusal of a surface it repaired that is still no solid
    (``slicer.repair``).

    Attributes:
        name: the file's name.
        tried: what ``--repair`` did and why the result is refused, one clause
            ("filled 3 holes (...) and wrapped it with fTetWild (...)").
    """

    def __init__(self, name: str, tried: str, fix: str) -> None:
        super().__init__(f"{name} is still refused after --repair {tried}", fix)
        self.name = name
        self.tried = tried
