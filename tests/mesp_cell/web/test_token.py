"""The console's bearer token: created 0600 once, checked in constant time; a console bound
beyond loopback refuses every API call without it (the app, without a cell)."""

from __future__ import annotations

import stat
from pathlib import Path

from fastapi.testclient import TestClient

from mesp_cell.web.api import build_app
from mesp_cell.web.context import ConsoleContext
from mesp_cell.web.live import LiveState
from mesp_cell.web.token import bearer_ok, is_loopback, load_token, token_path


def test_token_is_created_once_private_and_checked(tmp_path: Path) -> None:
    assert load_token(tmp_path, create=False) == ""
    token = load_token(tmp_path, create=True)
    assert len(token) >= 40 and load_token(tmp_path, create=True) == token
    assert stat.S_IMODE(token_path(tmp_path).stat().st_mode) == 0o600
    assert bearer_ok(token, f"Bearer {token}")
    assert not bearer_ok(token, f"Bearer {token}x") and not bearer_ok(token, token)
    assert not bearer_ok("", "Bearer ") and not bearer_ok(token, None)
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")


def test_a_console_bound_beyond_loopback_needs_the_token_everywhere(tmp_path: Path) -> None:
    token = load_token(tmp_path, create=True)
    ctx = ConsoleContext(cell="sim", home=tmp_path, db_path=tmp_path / "jobs.sqlite",
                         bus=None, live=LiveState(), token=token, token_all=True)  # type: ignore[arg-type]
    with TestClient(build_app(ctx)) as client:
        r = client.get("/api/jobs")
        assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
        assert "bearer token is required" in r.json()["detail"]
        assert client.get("/api/history").status_code == 401
        ok = client.get("/api/jobs", headers={"Authorization": f"Bearer {token}"})
        assert ok.status_code == 200 and ok.json() == []
        r = client.get("/api/jobs/x", headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 404
        assert client.get("/", follow_redirects=True).status_code == 200  # the page asks
        assert client.get("/static/../jobs.sqlite").status_code == 404
