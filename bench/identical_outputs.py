"""Are two job directories' outputs identical? For refactorings that must not change results.

Compares every file the two directories hold: each array of each ``.npz`` bit for bit
(``np.array_equal``, NaN equal to NaN, same dtype and shape), ``report.json`` value by value
except what differs from run to run (``IGNORED_KEYS``: times, memory, the tet cache's hit)
and the job directories' own paths, HTML byte for byte but plotly's random UUIDs, and every
other file (figures, PLY, text, TOML) byte for byte. Prints ``identical`` or one line
per difference and exits 0 or 1.

    .venv/bin/python bench/identical_outputs.py BEFORE_DIR AFTER_DIR [--skip-figures]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

#: report.json keys that differ from run to run whatever the code, at any depth: wall-clock
#: times, the peak memory, and whether the tet mesh came from the cache (shared by both runs
#: on purpose: fTetWild's meshing is not reproducible).
IGNORED_KEYS = frozenset({"timing_s", "field_timing_s", "timings", "seconds",
                          "ftetwild_seconds", "total_s", "peak_memory_mb", "cached"})
FIGURES = frozenset({".png", ".mp4"})
#: plotly names each figure's <div> with a fresh UUID (preview.html).
UUID = re.compile(rb"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


def npz_differences(a: Path, b: Path) -> Iterator[str]:
    """One line per array that differs (missing, dtype, shape or any element)."""
    with np.load(a, allow_pickle=False) as za, np.load(b, allow_pickle=False) as zb:
        for name in sorted(set(za.files) | set(zb.files)):
            if name not in za.files or name not in zb.files:
                yield f"{a.name}: array {name} only in {'after' if name in zb.files else 'before'}"
                continue
            x, y = za[name], zb[name]
            if x.dtype != y.dtype or x.shape != y.shape:
                yield f"{a.name}:{name}: {x.dtype}{x.shape} vs {y.dtype}{y.shape}"
                continue
            nan = x.dtype.kind in "fc"
            if not np.array_equal(x, y, equal_nan=nan):
                diff = np.flatnonzero(~((x == y) | (np.isnan(x) & np.isnan(y)) if nan
                                        else x == y).ravel())
                worst = (float(np.nanmax(np.abs(x.astype(float) - y.astype(float))))
                         if x.dtype.kind in "fciub" else float("nan"))
                yield (f"{a.name}:{name}: {diff.size} of {x.size} elements differ "
                       f"(first at flat index {int(diff[0])}, largest difference {worst:.3g})")


def json_differences(x: Any, y: Any, where: str, paths: tuple[str, str]) -> Iterator[str]:
    """One line per differing value of two parsed JSON documents (``IGNORED_KEYS`` skipped,
    the before directory's path read as the after one's)."""
    if isinstance(x, dict) and isinstance(y, dict):
        for key in list(x) + [k for k in y if k not in x]:
            if key in IGNORED_KEYS:
                continue
            if key not in x or key not in y:
                yield f"{where}.{key}: only in {'after' if key in y else 'before'}"
                continue
            yield from json_differences(x[key], y[key], f"{where}.{key}", paths)
        if list(k for k in x if k in y) != list(k for k in y if k in x):
            yield f"{where}: keys in another order"
    elif isinstance(x, list) and isinstance(y, list):
        if len(x) != len(y):
            yield f"{where}: {len(x)} vs {len(y)} items"
        for i, (u, v) in enumerate(zip(x, y, strict=False)):
            yield from json_differences(u, v, f"{where}[{i}]", paths)
    elif isinstance(x, str) and isinstance(y, str):
        if x.replace(paths[0], paths[1]) != y:
            yield f"{where}: {x!r} vs {y!r}"
    elif isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return
    elif type(x) is not type(y) or x != y:
        yield f"{where}: {x!r} vs {y!r}"


def differences(before: Path, after: Path, skip_figures: bool = False) -> list[str]:
    """Every difference between the two job directories' files."""
    names_a = {p.relative_to(before) for p in before.rglob("*") if p.is_file()}
    names_b = {p.relative_to(after) for p in after.rglob("*") if p.is_file()}
    out: list[str] = []
    for rel in sorted(names_a | names_b):
        if skip_figures and rel.suffix in FIGURES:
            continue
        if rel not in names_a or rel not in names_b:
            out.append(f"{rel}: only in {'after' if rel in names_b else 'before'}")
            continue
        a, b = before / rel, after / rel
        if rel.suffix == ".npz":
            out += npz_differences(a, b)
        elif rel.suffix == ".json":
            paths = (str(before.resolve()), str(after.resolve()))
            out += json_differences(json.loads(a.read_text()), json.loads(b.read_text()),
                                    str(rel), paths)
        elif rel.suffix == ".html":
            if UUID.sub(b"UUID", a.read_bytes()) != UUID.sub(b"UUID", b.read_bytes()):
                out.append(f"{rel}: bytes differ (UUIDs aside)")
        elif a.read_bytes() != b.read_bytes():
            out.append(f"{rel}: bytes differ")
    return out


def main(argv: list[str] | None = None) -> int:
    """Compare two job directories; exit 0 if identical."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before", type=Path, help="job directory written by the old code")
    p.add_argument("after", type=Path, help="job directory written by the new code")
    p.add_argument("--skip-figures", action="store_true", help="do not compare PNG/MP4 files")
    args = p.parse_args(argv)
    for d in (args.before, args.after):
        if not d.is_dir():
            print(f"bench: error: {d} is not a directory; pass two job directories",
                  file=sys.stderr)
            return 2
    found = differences(args.before, args.after, args.skip_figures)
    if not found:
        print(f"identical: {args.before} and {args.after}")
        return 0
    print("\n".join(found))
    print(f"{len(found)} differences")
    return 1


if __name__ == "__main__":
    sys.exit(main())
