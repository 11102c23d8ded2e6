"""Freed heap goes back to the OS after a long command."""

from __future__ import annotations

import numpy as np

from mesp_cell.heap import give_back


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


def test_freed_small_blocks_go_back() -> None:
    # many small blocks (below mmap's threshold) stay in the heap when freed
    blocks = [np.ones(2000) for _ in range(20000)]  # ~16 kB each, ~300 MiB
    keep = blocks[::500]  # a few survivors pin the heap's top
    del blocks
    before = _rss_mib()
    assert give_back()
    after = _rss_mib()
    assert after < before - 100, (before, after)
    assert keep
