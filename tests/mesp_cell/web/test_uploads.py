"""Uploads: stored under generated names inside the job directory, size-limited, checked."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.web.uploads import TooLarge, safe_stem, store_upload

CUBE = Path(__file__).resolve().parents[3] / "examples" / "cube.stl"


def test_no_client_name_becomes_a_path(tmp_path: Path) -> None:
    assert safe_stem("../../etc/passwd.stl") == "passwd"
    assert safe_stem("C:\\Users\\me\\My Part (2).STL") == "my-part-2"
    assert safe_stem("..stl") == "model" and safe_stem(None) == "model"
    model, job = store_upload(tmp_path, io.BytesIO(CUBE.read_bytes()), "../../x/My Cube.stl",
                              io.BytesIO(b""), 1 << 20)
    assert model.parent.parent == tmp_path / "uploads" and model.name == "my-cube.stl"
    assert job is None


def test_refused_uploads_leave_nothing(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"unsupported type '\.exe'"):
        store_upload(tmp_path, io.BytesIO(b"x"), "a.exe", None, 1 << 20)
    with pytest.raises(TooLarge, match="larger than 1 MiB"):
        store_upload(tmp_path, io.BytesIO(b"x" * ((1 << 20) + 1)), "a.stl", None, 1 << 20)
    with pytest.raises(InputError, match="TOML"):
        store_upload(tmp_path, io.BytesIO(CUBE.read_bytes()), "a.stl",
                     io.BytesIO(b"[slicing\n"), 1 << 20)
    assert not list((tmp_path / "uploads").iterdir())
