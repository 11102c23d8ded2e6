"""The cell's secret: made once, 0600 in a 0700 folder, the same for every process; a key
file others can read is refused."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.bus.secret import cell_secret, key_path, write_private


def test_made_at_first_use_private_and_stable(tmp_path: Path) -> None:
    assert cell_secret("sim", tmp_path, create=False) is None
    key = cell_secret("sim", tmp_path)
    assert key is not None and len(key) == 32
    assert cell_secret("sim", tmp_path) == key
    assert cell_secret("other", tmp_path) != key
    path = key_path("sim", tmp_path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700


def test_a_key_others_can_read_or_a_corrupt_one_is_refused(tmp_path: Path) -> None:
    cell_secret("sim", tmp_path)
    path = key_path("sim", tmp_path)
    path.chmod(0o644)
    with pytest.raises(InputError, match="can be read or changed by other users"):
        cell_secret("sim", tmp_path)
    path.chmod(0o600)
    path.write_text("not hex")
    with pytest.raises(InputError, match="corrupt"):
        cell_secret("sim", tmp_path)


def test_state_files_are_written_private(tmp_path: Path) -> None:
    write_private(tmp_path / "run.json", "{}")
    assert stat.S_IMODE((tmp_path / "run.json").stat().st_mode) == 0o600
    assert (tmp_path / "run.json").read_text() == "{}"
