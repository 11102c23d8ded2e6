"""Draw the package dependency graph of the code, read from its imports (docs/architecture.png).

Every ``.py`` file of the project's packages (the top-level directories with an ``__init__.py``:
slicer, planner, sim, mesp_cell, and any added later) is parsed with :mod:`ast`; each
``import`` and ``from ... import`` naming a project module is one edge, wherever it sits in the
file (top level, inside a function, under ``TYPE_CHECKING``). Each top-level package is one
box (its sub-packages, module and line counts inside), placed in rows by what it imports, the
libraries at the bottom; each importing pair is one arrow naming the modules imported across,
red where it points up the layering. Import cycles between modules are listed under the graph.

    python docs/architecture.py            # writes docs/architecture.png, prints the edges
    python docs/architecture.py --out X.png --quiet
"""

from __future__ import annotations

import argparse
import ast
import textwrap
from collections import defaultdict
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

ROOT = Path(__file__).resolve().parents[1]
#: Libraries first, in the order they may depend on each other; packages not named here
#: (a new one) are placed by their imports.
KNOWN_ORDER = ("core", "slicer", "planner", "sim", "mesp_cell")
COLOURS = {"core": "#7f7f7f", "slicer": "#1f77b4", "planner": "#2ca02c", "sim": "#ff7f0e",
           "mesp_cell": "#9467bd"}


class Edge(NamedTuple):
    """One import: module ``src`` imports module ``dst`` (dotted names), at ``line``."""

    src: str
    dst: str
    line: int


def packages(root: Path) -> list[str]:
    """Top-level directories of ``root`` that are Python packages (have ``__init__.py``)."""
    skip = {"tests", "bench", "examples", "docs", "launch", "build"}
    return sorted(p.name for p in root.iterdir()
                  if p.is_dir() and p.name not in skip and (p / "__init__.py").is_file())


def modules(root: Path, pkgs: list[str]) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of ``pkgs`` (a package by its
    ``__init__``)."""
    out: dict[str, Path] = {}
    for pkg in pkgs:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _resolve(name: str, known: dict[str, Path]) -> str | None:
    """The longest prefix of ``name`` that is a project module, or None (a library)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in known:
            return candidate
    return None


def imports(known: dict[str, Path]) -> list[Edge]:
    """Every import between project modules (self-imports dropped)."""
    edges: list[Edge] = []
    for mod, path in known.items():
        is_pkg = path.name == "__init__.py"
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Import | ast.ImportFrom):
                continue
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                if node.level:  # relative: from the package holding this module
                    base = mod.split(".")
                    base = base[: len(base) - node.level + (1 if is_pkg else 0)]
                    prefix = ".".join(base + ([node.module] if node.module else []))
                else:
                    prefix = node.module or ""
                # `from pkg import mod` names a module where one exists, else a symbol of pkg
                targets = [f"{prefix}.{a.name}" for a in node.names] or [prefix]
            for name in targets:
                dst = _resolve(name, known)
                if dst is not None and dst != mod:
                    edges.append(Edge(mod, dst, node.lineno))
    return edges


def cycles(edges: list[Edge]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    graph: dict[str, set[str]] = defaultdict(set)
    for e in edges:
        graph[e.src].add(e.dst)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def levels(order: list[str], across: dict[tuple[str, str], int]) -> dict[str, int]:
    """Row of each top-level package: the longest chain of imports below it, counting only
    imports down the order (an import up the order is a violation, drawn but not laid out)."""
    level: dict[str, int] = {}
    for p in order:  # bottom to top: what p imports is already placed
        below = [level[b] for (a, b) in across if a == p and b in level]
        level[p] = 1 + max(below, default=-1)
    return level


def _overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """Overlap area of two rectangles given as (centre x, centre y, half width, half height)."""
    dx = min(a[0] + a[2], b[0] + b[2]) - max(a[0] - a[2], b[0] - b[2])
    dy = min(a[1] + a[3], b[1] + b[3]) - max(a[1] - a[3], b[1] - b[3])
    return max(dx, 0.0) * max(dy, 0.0)


def _label_place(p0: tuple[float, float], p1: tuple[float, float], lines: int,
                 boxes: list[tuple[float, float, float, float]],
                 taken: list[tuple[float, float, float, float]]) -> tuple[float, float]:
    """A point along the arrow p0 -> p1 where a label of ``lines`` text lines overlaps the
    package boxes and the labels placed before it least (appended to ``taken``)."""
    best: tuple[float, float, float] | None = None
    for t in (0.5, 0.35, 0.65, 0.25, 0.75, 0.42, 0.58):
        x, y = p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1])
        rect = (x, y, 1.3, 0.09 * lines + 0.12)
        cost = sum(_overlap(rect, r) for r in boxes + taken)
        if best is None or cost < best[0] - 1e-9:
            best = (cost, x, y)
    assert best is not None
    taken.append((best[1], best[2], 1.3, 0.09 * lines + 0.12))
    return best[1], best[2]


def _box_lines(pkg: str, known: dict[str, Path]) -> list[str]:
    """The text of a package's box: its own modules, then each sub-package, with counts."""
    subs: dict[str, list[str]] = defaultdict(list)
    for m in known:
        parts = m.split(".")
        if parts[0] != pkg:
            continue
        nested = len(parts) > 2 or (len(parts) == 2 and known[m].name == "__init__.py")
        subs[parts[1] if nested else ""].append(m)
    loc = {s: sum(len(known[m].read_text().splitlines()) for m in ms) for s, ms in subs.items()}
    lines = [f"{pkg}/  {len(subs.get('', []))} modules, {loc.get('', 0):,} lines"]
    return lines + [f"  {s}/  {len(subs[s])} modules, {loc[s]:,} lines"
                    for s in sorted(subs) if s]


def draw(known: dict[str, Path], edges: list[Edge], out: Path) -> None:
    """One box per top-level package (its sub-packages, module and line counts inside), one
    arrow per importing pair (width ~ number of imports) labelled with the modules imported
    across; arrows against the order in red; import cycles between modules listed below."""
    pkgs = sorted({m.split(".")[0] for m in known})
    order = [p for p in KNOWN_ORDER if p in pkgs] + [p for p in pkgs if p not in KNOWN_ORDER]
    across: dict[tuple[str, str], set[str]] = defaultdict(set)
    count: dict[tuple[str, str], int] = defaultdict(int)
    for e in edges:
        a, b = e.src.split(".")[0], e.dst.split(".")[0]
        if a != b:
            across[(a, b)].add(e.dst[len(b) + 1:] or "__init__")
            count[(a, b)] += 1
    level = levels(order, count)
    by_level: dict[int, list[str]] = defaultdict(list)
    for p in order:
        by_level[level[p]].append(p)
    pos: dict[str, tuple[float, float]] = {}
    for lv, ps in by_level.items():
        zig = (0.0, 4.2, -4.2)[lv % 3] if len(ps) == 1 else 0.0
        for i, p in enumerate(ps):
            pos[p] = (zig + (i - (len(ps) - 1) / 2) * 8.4, lv * 3.4)
    box_text = {p: _box_lines(p, known) for p in pos}
    # centre, half width, half height of each package box (as drawn below, with its padding)
    boxes = [(x, y, 2.4, 0.38 + 0.15 * len(box_text[p])) for p, (x, y) in pos.items()]
    taken: list[tuple[float, float, float, float]] = []
    fig, ax = plt.subplots(figsize=(12, 3.0 * len(by_level) + 1.5))
    for (a, b), n in sorted(count.items()):
        (x0, y0), (x1, y1) = pos[a], pos[b]
        wrong = order.index(b) > order.index(a)
        colour = "#d62728" if wrong else COLOURS.get(b, "#555555")
        ax.add_patch(FancyArrowPatch(
            (x0, y0), (x1, y1), arrowstyle="-|>", mutation_scale=18,
            lw=0.8 + 0.35 * n ** 0.5, color=colour, alpha=0.8, shrinkA=48, shrinkB=48,
            zorder=1))
        names = textwrap.fill(", ".join(sorted(across[(a, b)])), 34)
        label = f"{a} -> {b}: {n} imports of\n{names}"
        mx, my = _label_place((x0, y0), (x1, y1), label.count("\n") + 1, boxes, taken)
        ax.text(mx, my, label, fontsize=7.5, ha="center",
                va="center", color=colour, zorder=3,
                bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": colour, "lw": 0.6})
    for p, (x, y) in pos.items():
        lines = box_text[p]
        h = 0.55 + 0.3 * len(lines)
        ax.add_patch(FancyBboxPatch((x - 2.3, y - h / 2), 4.6, h, boxstyle="round,pad=0.08",
                                    fc=COLOURS.get(p, "#cccccc"), ec="black", lw=0.8,
                                    zorder=2))
        ax.text(x, y + h / 2 - 0.3, p, ha="center", va="center", fontsize=12,
                weight="bold", color="white", zorder=4)
        ax.text(x - 2.15, y + h / 2 - 0.55, "\n".join(lines), ha="left", va="top",
                fontsize=7.5, color="white", family="monospace", zorder=4)
    found = cycles(edges)
    text = ("import cycles between modules: " + "; ".join(" <-> ".join(c) for c in found)
            if found else "no import cycles between modules")
    wrong_n = sum(n for (a, b), n in count.items() if order.index(b) > order.index(a))
    text += (f"\nimports against the layering {' > '.join(reversed(order))} (red): {wrong_n}"
             "\nevery import counted, at the top of a file or inside a function")
    xs = [x for x, _ in pos.values()]
    ys = [y for _, y in pos.values()]
    ax.text(min(xs) - 2.4, min(ys) - 1.6, text, fontsize=8.5, va="top")
    ax.set_xlim(min(xs) - 3.0, max(xs) + 3.0)
    ax.set_ylim(min(ys) - 2.6, max(ys) + 1.6)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title("MESP Cell: package dependencies read from the imports "
                 "(python docs/architecture.py)", fontsize=11)
    fig.tight_layout()
    fig.savefig(out, dpi=80, bbox_inches="tight")
    plt.close(fig)


def summary(known: dict[str, Path], edges: list[Edge]) -> str:
    """Per pair of top-level packages, the modules imported across (for docs/architecture.md)."""
    across: dict[tuple[str, str], set[str]] = defaultdict(set)
    for e in edges:
        a, b = e.src.split(".")[0], e.dst.split(".")[0]
        if a != b:
            across[(a, b)].add(e.dst)
    out = [f"{a} -> {b}: {', '.join(sorted(ms))}" for (a, b), ms in sorted(across.items())]
    out += ["cycle: " + " <-> ".join(c) for c in cycles(edges)]
    return "\n".join(out)


def main() -> None:
    """Parse the packages, write the picture, print the cross-package imports."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "architecture.png")
    parser.add_argument("--quiet", action="store_true", help="do not print the imports")
    args = parser.parse_args()
    known = modules(ROOT, packages(ROOT))
    edges = imports(known)
    draw(known, edges, args.out)
    if not args.quiet:
        print(summary(known, edges))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
