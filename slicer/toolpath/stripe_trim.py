"""Stripe ends cut back where they converge on a longer stripe.

Where the stripe count must fall (disc-like layers: radial stripes towards the centre), the
stripe field lets the stripes that end converge on their neighbours for a few widths before the
branch point: the spacing drops to 0.5-0.8 W, the material overlaps, and the volume match then
widens every stripe of the layer. ``trim_converging`` cuts such ends back to CONVERGE_TRIM x
spacing from the longer neighbour (a gap of at most 2 x 0.7 = 1.4 W stays, against an overlap
of up to 1 W). Measured effect: docs/benchmarks.md ("Moved from docstrings", stripes).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from slicer.toolpath.eikonal import segment_feet
from slicer.toolpath.lines import SurfaceLines

CONVERGE_TRIM = 0.7  # open stripe ends closer than this x spacing to a longer stripe are cut
TRIM_REACH = 8.0  # ... within this x spacing (arc length) of the end


def trim_converging(lines: SurfaceLines, spacing: float, ratio: float = CONVERGE_TRIM,
                    rounds: int = 1, reach: float = TRIM_REACH) -> SurfaceLines:
    """Cut open stripes back from their ends where they run into a longer stripe.

    Where the stripe count must fall (towards the centre of a radial pattern, at a branch
    point), the stripe that ends converges on its neighbours for a few widths before it
    stops: there the spacing drops to W/2 and less, the material overlaps, and the volume
    match widens every other stripe of the layer to pay for it. Lines are ranked by length
    (longest first); an open line's end points whose distance to the nearest segment of a
    longer line is below ``ratio`` x ``spacing`` are dropped, from each end up to the first
    point that keeps its distance (the line stays one piece; a line with no such point is
    dropped). Only points within ``reach`` x spacing (arc length) of an open end are tested:
    a converging end is a few widths long, and the rest of a long stripe costs time for
    nothing. ``rounds`` passes, each against the lines the previous one kept (one is the
    default: a second changes next to nothing).
    """
    out = lines
    for _ in range(rounds):  # loop over passes
        if out.n_lines < 2:
            return out
        ln = out.line.astype(np.int64)
        p = out.points
        seg_ok = ln[1:] == ln[:-1]
        seg = np.flatnonzero(seg_ok)
        if len(seg) == 0:
            return out
        length = np.bincount(ln[seg], weights=np.linalg.norm(p[seg + 1] - p[seg], axis=1),
                             minlength=out.n_lines)
        rank = np.empty(out.n_lines, dtype=np.int64)
        rank[np.argsort(-length, kind="stable")] = np.arange(out.n_lines)
        a, b = p[seg], p[seg + 1]
        step = np.zeros(len(p))
        step[seg + 1] = np.linalg.norm(b - a, axis=1)
        arc = np.cumsum(step)
        head = np.flatnonzero(np.concatenate([[True], ln[1:] != ln[:-1]]))
        size = np.diff(np.concatenate([head, [len(p)]]))
        tail = head + size - 1
        from_end = np.minimum(arc - np.repeat(arc[head], size), np.repeat(arc[tail], size) - arc)
        test = np.flatnonzero((from_end <= reach * spacing) & ~out.closed[ln])
        if len(test) == 0:
            return out
        # (point, segment) pairs whose midpoints lie within ratio x spacing + half a segment; a
        # segment longer than the 95th percentile may be missed near its ends (less trimming)
        half = 0.5 * float(np.percentile(np.linalg.norm(b - a, axis=1), 95))
        pairs = cKDTree(p[test]).sparse_distance_matrix(cKDTree(0.5 * (a + b)),
                                                  ratio * spacing + half,
                                                  output_type="ndarray")
        pi, si = test[pairs["i"]], pairs["j"]
        longer = rank[ln[seg[si]]] < rank[ln[pi]]
        pi, si = pi[longer], si[longer]
        close = segment_feet(p[pi], a[si], b[si])[0] < ratio * spacing
        bad = np.zeros(len(p), dtype=bool)
        bad[pi[close]] = True
        if not bad.any():
            return out
        # per line: keep from the first good point to the last good point
        pos = np.arange(len(p)) - np.repeat(head, size)
        good = ~bad
        big = np.iinfo(np.int64).max
        first = np.full(out.n_lines, big)
        last = np.full(out.n_lines, -1)
        np.minimum.at(first, ln[good], pos[good])
        np.maximum.at(last, ln[good], pos[good])
        keep = (pos >= first[ln]) & (pos <= last[ln])
        counts = np.bincount(ln[keep], minlength=out.n_lines)
        keep &= counts[ln] >= 2
        kept_line = counts >= 2
        renum = np.cumsum(kept_line) - 1
        out = SurfaceLines(points=p[keep], face=out.face[keep], bary=out.bary[keep],
                           line=renum[ln[keep]].astype(np.int32),
                           closed=out.closed[kept_line])
    return out
