"""The immutable pipeline stages and their files (design.md, "Artifacts").

Each stage is a frozen dataclass of read-only numpy arrays that saves to and loads from
its ``.npz`` file in a job directory. Nothing mutates a stage in place: a later stage is a
new value computed from earlier ones. Each array is declared once, as a ``column`` (dtype and
row shape); the file's schema and the dtypes follow from that declaration.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from enum import IntEnum
from pathlib import Path
from typing import Any, ClassVar, NamedTuple, Self

import numpy as np

from core.artifacts import Schema, load_npz, save_npz
from core.errors import InputError

#: Rows of any stage array at most (50 M tets / waypoints: far beyond a printable part).
MAX_ROWS = 50_000_000
#: Coordinates of a model or toolpath in mm, at most this far from the origin.
MAX_COORDINATE_MM = 10_000.0
#: A waypoint's layer height (mm), width (mm) and speed (mm/s) at most.
MAX_HEIGHT_MM, MAX_WIDTH_MM, MAX_SPEED_MM_S = 20.0, 100.0, 10_000.0


def _frozen(arr: np.ndarray, dtype: type | np.dtype) -> np.ndarray:
    out = np.ascontiguousarray(arr, dtype=dtype)
    if out is arr or out.base is not None:
        out = out.copy()
    out.setflags(write=False)
    return out


class Column(NamedTuple):
    """One array of a stage file: its dtype and the shape of one row (``()``: a scalar)."""

    dtype: type
    row: tuple[int, ...] = ()

    @property
    def schema(self) -> tuple[int, str, tuple[int, ...] | None]:
        """(ndim, accepted dtype kinds, trailing shape or None) as ``load_npz`` checks it; a
        file may hold any integer width where the stage keeps integers."""
        kind = np.dtype(self.dtype).kind
        return (1 + len(self.row), "iu" if kind in "iu" else kind, self.row or None)


def column(dtype: type, *row: int) -> Any:
    """Declare a stage array: ``vertices: np.ndarray = column(np.float64, 3)`` is an (n, 3)
    float64 array (a dataclass field without default; ``Stage`` reads the declaration)."""
    return dataclasses.field(metadata={"column": Column(dtype, tuple(row))})


class Stage:
    """Base of the pipeline stages: save/load of the stage file (FILE, SCHEMA, DTYPES).

    A subclass declares its arrays with ``column``; SCHEMA and DTYPES are derived from those
    declarations (a subclass may still set both by hand).
    """

    FILE: ClassVar[str]
    SCHEMA: ClassVar[Schema]
    DTYPES: ClassVar[dict[str, type]]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        columns = {name: value.metadata["column"] for name, value in vars(cls).items()
                   if isinstance(value, dataclasses.Field) and "column" in value.metadata}
        if columns:
            cls.SCHEMA = {name: c.schema for name, c in columns.items()}
            cls.DTYPES = {name: c.dtype for name, c in columns.items()}

    def _freeze(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if f.name in self.DTYPES:
                object.__setattr__(self, f.name, _frozen(value, self.DTYPES[f.name]))

    def arrays(self) -> dict[str, np.ndarray]:
        """The stage's arrays by their file names."""
        return {name: getattr(self, name) for name in self.DTYPES}

    def save(self, job_dir: Path) -> Path:
        """Write the stage file into ``job_dir`` atomically; returns its path."""
        path = Path(job_dir) / self.FILE
        save_npz(path, self.arrays())
        return path

    @classmethod
    def load(cls, job_dir: Path) -> Self:
        """Read the stage file from ``job_dir``; a missing or malformed file is an InputError:
        mis-shaped or inconsistent arrays, a NaN or infinite number, more rows than
        ``MAX_ROWS``, or values the stage cannot hold (``check``)."""
        path = Path(job_dir) / cls.FILE
        arrays = load_npz(path, cls.SCHEMA)
        writer = "mesp plan" if cls.FILE == "trajectory.npz" else "mesp slice"
        fix = f"re-run the stage that writes it ({writer})"
        for name, arr in arrays.items():
            if name in cls.DTYPES and len(arr) > MAX_ROWS:
                raise InputError(f"{path}: '{name}' has {len(arr):,} rows, more than {MAX_ROWS:,}",
                                 fix)
            if name in cls.DTYPES and arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
                raise InputError(f"{path}: '{name}' holds NaN or infinite values", fix)
        try:
            stage = cls(**{name: arrays[name] for name in cls.DTYPES})
        except (ValueError, TypeError, OverflowError) as exc:
            raise InputError(f"{path} is inconsistent ({exc})", fix) from exc
        problem = stage.check()
        if problem:
            raise InputError(f"{path}: {problem}", fix)
        return stage

    def check(self) -> str:
        """'' if the values are ones the later stages can use, else what is wrong (a file
        from outside: ``load`` refuses it)."""
        return ""


@dataclass(frozen=True, eq=False)
class TetMesh(Stage):
    """A tetrahedral mesh of the solid.

    Attributes:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int32, vertex indices, positively oriented (det of edges > 0).
    """

    vertices: np.ndarray = column(np.float64, 3)
    tets: np.ndarray = column(np.int32, 4)

    FILE: ClassVar[str] = "tetmesh.npz"

    def __post_init__(self) -> None:
        self._freeze()
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (V, 3), got {self.vertices.shape}")
        if self.tets.ndim != 2 or self.tets.shape[1] != 4:
            raise ValueError(f"tets must be (T, 4), got {self.tets.shape}")
        if self.tets.size and (self.tets.min() < 0 or self.tets.max() >= len(self.vertices)):
            raise ValueError("tets index outside vertices")

    def check(self) -> str:
        """'' if the mesh has tets within ``MAX_COORDINATE_MM`` of the origin."""
        if len(self.tets) == 0:
            return "the tet mesh has no tet"
        if np.abs(self.vertices).max() > MAX_COORDINATE_MM:
            return f"a vertex lies beyond {MAX_COORDINATE_MM:g} mm of the origin"
        return ""


@dataclass(frozen=True, eq=False)
class Field(Stage):
    """The slicing scalar field and the iso-values of the layers.

    Attributes:
        g: (V,) float64, scalar field on tet vertices (mm-like: its gradient norm is ~1
            where the layer height equals the target).
        iso: (L,) float64, iso-value of each layer, increasing in print order.
    """

    g: np.ndarray = column(np.float64)
    iso: np.ndarray = column(np.float64)

    FILE: ClassVar[str] = "field.npz"

    def __post_init__(self) -> None:
        self._freeze()
        if self.iso.size > 1 and np.any(np.diff(self.iso) <= 0):
            raise ValueError("iso-values must increase")


@dataclass(frozen=True, eq=False)
class Layers(Stage):
    """All curved layers as one triangle soup-with-sharing, tagged per face.

    Attributes:
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32, vertex indices; oriented so the face normal points along the
            growth direction (away from material already printed).
        face_layer: (m,) int32, layer index of each face (0 = printed first).
        vertex_height: (n,) float64, mm, physical distance to the next layer along the
            growth direction.
        vertex_direction: (n, 3) float64, unit printing direction (normalised field gradient).
    """

    vertices: np.ndarray = column(np.float64, 3)
    faces: np.ndarray = column(np.int32, 3)
    face_layer: np.ndarray = column(np.int32)
    vertex_height: np.ndarray = column(np.float64)
    vertex_direction: np.ndarray = column(np.float64, 3)

    FILE: ClassVar[str] = "layers.npz"

    def __post_init__(self) -> None:
        self._freeze()
        n, m = len(self.vertices), len(self.faces)
        if self.face_layer.shape != (m,):
            raise ValueError("face_layer must have one entry per face")
        if self.vertex_height.shape != (n,) or self.vertex_direction.shape != (n, 3):
            raise ValueError("vertex_height and vertex_direction need one entry per vertex")
        if m and (self.faces.min() < 0 or self.faces.max() >= n):
            raise ValueError("faces index outside vertices")

    @property
    def layer_count(self) -> int:
        """Number of layers (max layer index + 1)."""
        return int(self.face_layer.max()) + 1 if len(self.face_layer) else 0

    def layer(self, index: int) -> LayerMesh:
        """One layer as a compact triangle mesh with its own vertex numbering."""
        faces = self.faces[self.face_layer == index]
        used, inverse = np.unique(faces, return_inverse=True)
        return LayerMesh(
            index=index,
            vertices=self.vertices[used],
            faces=inverse.reshape(-1, 3).astype(np.int32),
            height=self.vertex_height[used],
            direction=self.vertex_direction[used],
        )


@dataclass(frozen=True, eq=False)
class LayerMesh:
    """One layer (possibly several connected components) with its own numbering.

    Attributes:
        index: int, layer index.
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32.
        height: (n,) float64, mm, layer height H.
        direction: (n, 3) float64, unit printing direction.
    """

    index: int
    vertices: np.ndarray
    faces: np.ndarray
    height: np.ndarray
    direction: np.ndarray


class Pattern(IntEnum):
    """The fill pattern of a waypoint's layer, as ``toolpath.npz`` stores it (int8).

    An ``IntEnum``: the stored values stay the integers of design.md and numpy arrays compare
    with the members directly (``toolpath.pattern == Pattern.STRIPE``); ``label`` is the
    name reports use.
    """

    CONTOUR = 0  # boundary-conformal contours (paper section 4.3)
    STRIPE = 1  # parallel stripes

    @property
    def label(self) -> str:
        """"contour" or "stripe" (report.json keys)."""
        return self.name.lower()


@dataclass(frozen=True, eq=False)
class Toolpath(Stage):
    """Waypoints in print order (design.md, ``toolpath.npz``).

    Attributes:
        position: (N, 3) float64, mm, nozzle tip in the model frame.
        normal: (N, 3) float64, unit printing direction; the nozzle approaches along -normal.
        layer: (N,) int32, layer index.
        path: (N,) int32, id of a continuous extrusion path, increasing in print order.
        height: (N,) float64, mm, layer height H.
        width: (N,) float64, mm, target toolpath width W.
        speed: (N,) float64, mm/s, nozzle speed v.
        extrude: (N,) bool, False = travel without deposition.
        pattern: (N,) int8, a ``Pattern``: 0 = boundary-conformal contour, 1 = stripe.
    """

    position: np.ndarray = column(np.float64, 3)
    normal: np.ndarray = column(np.float64, 3)
    layer: np.ndarray = column(np.int32)
    path: np.ndarray = column(np.int32)
    height: np.ndarray = column(np.float64)
    width: np.ndarray = column(np.float64)
    speed: np.ndarray = column(np.float64)
    extrude: np.ndarray = column(np.bool_)
    pattern: np.ndarray = column(np.int8)

    FILE: ClassVar[str] = "toolpath.npz"

    def __post_init__(self) -> None:
        self._freeze()
        n = len(self.position)
        for name in self.DTYPES:
            if len(getattr(self, name)) != n:
                raise ValueError(f"'{name}' has {len(getattr(self, name))} rows, expected {n}")

    def __len__(self) -> int:
        return len(self.position)

    def check(self) -> str:
        """'' if every waypoint can be printed, else the first problem: no waypoint, none
        extruding, a coordinate beyond ``MAX_COORDINATE_MM``, a normal not of unit length, a
        height, width or speed not > 0 or above its ``MAX_*``, a negative layer or path, an
        unknown pattern."""
        if len(self) == 0:
            return "the toolpath has no waypoint"
        if not self.extrude.any():
            return "the toolpath deposits nothing (no waypoint extrudes)"
        if np.abs(self.position).max() > MAX_COORDINATE_MM:
            return (f"a waypoint lies {np.abs(self.position).max():.3g} mm from the origin, "
                    f"beyond {MAX_COORDINATE_MM:g} mm")
        with np.errstate(over="ignore"):  # a normal of 1e300 is refused below, not warned
            norm = np.linalg.norm(self.normal, axis=1)
        if np.any(np.abs(norm - 1.0) > 1e-3):
            return f"normal {int(np.argmax(np.abs(norm - 1.0)))} is not a unit vector"
        for name, top in (("height", MAX_HEIGHT_MM), ("width", MAX_WIDTH_MM),
                          ("speed", MAX_SPEED_MM_S)):
            values = getattr(self, name)
            if values.min() <= 0:
                return f"'{name}' of waypoint {int(np.argmin(values))} is {values.min():g}, not > 0"
            if values.max() > top:
                return (f"'{name}' of waypoint {int(np.argmax(values))} is {values.max():.3g}, "
                        f"above {top:g}")
        for name in ("layer", "path"):
            if getattr(self, name).min() < 0:
                return f"'{name}' holds a negative index"
        if not np.isin(self.pattern, list(Pattern)).all():
            return "'pattern' holds a value other than 0 (contour) or 1 (stripe)"
        return ""
