"""The size and quality record of a tet mesh (report.json ``mesh``, the tet cache's entries)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class TetStats:
    """Size and quality of a tet mesh (for the report and the benchmark).

    Attributes:
        tets: number of tets.
        vertices: number of vertices.
        mean_edge_mm: mean length of the unique edges, mm.
        min_dihedral_deg: smallest dihedral angle, deg (a regular tet has 70.53).
        max_dihedral_deg: largest dihedral angle, deg.
        sliver_fraction: fraction of tets with a dihedral angle below ``SLIVER_DEG`` (robust
            where the single smallest angle is one unlucky tet).
        mean_quality: mean radius ratio 3 r_in / r_circ (1 = regular tet, 0 = flat).
        worst_quality: smallest radius ratio.
        volume_mm3: total tet volume, mm^3.
        surface_volume_mm3: volume enclosed by the input surface, mm^3 (nan if unknown).
        volume_error: volume_mm3 / surface_volume_mm3 - 1.
        seconds: wall-clock time of the whole tetrahedralisation (fTetWild and refinement), s.
        reoriented: tets whose vertex order was flipped to make them positive.
        refinements: red refinements after fTetWild (``[mesh] refine``).
        ftetwild_tets: tets fTetWild produced (before the refinements).
        ftetwild_seconds: wall-clock time of fTetWild alone, s.
        snapped_mm_max: mm, the largest move of a refined boundary vertex onto the surface.
        refine_fallback: refine = "auto" meshed directly after the refined mesh failed or
            missed the solid's volume by more than ``AUTO_MAX_VOLUME_ERROR``.
        cached: the mesh was read back from the cache (``slicer.tet_cache``), not made now
            (the times are those of the run that made it).
    """

    tets: int
    vertices: int
    mean_edge_mm: float
    min_dihedral_deg: float
    max_dihedral_deg: float
    sliver_fraction: float
    mean_quality: float
    worst_quality: float
    volume_mm3: float
    surface_volume_mm3: float
    volume_error: float
    seconds: float
    reoriented: int = 0
    refinements: int = 0
    ftetwild_tets: int = 0
    ftetwild_seconds: float = 0.0
    snapped_mm_max: float = 0.0
    refine_fallback: bool = False
    cached: bool = False

    def as_dict(self) -> dict[str, Any]:
        """Plain values for report.json (``mesh`` section)."""
        return asdict(self)
