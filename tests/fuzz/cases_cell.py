"""Malformed inputs of the running cell: launch files and job submissions (see cases.py)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from tests.fuzz import fixtures
from tests.fuzz.case import Case, write_file


def _launch(text: str) -> Callable[[Path], list[str]]:
    return lambda tmp: ["launch", str(write_file(tmp / "launch.toml", text)), "--log-dir",
                        str(tmp / "logs")]


LAUNCH_CASES = [
    Case("launch", "heartbeat_timeout a string",
         _launch(fixtures.LAUNCH_OK.replace("heartbeat_timeout = 5.0",
                                            "heartbeat_timeout = \"soon\""))),
    Case("launch", "max_restarts a string",
         _launch(fixtures.LAUNCH_OK.replace("restart = \"never\"",
                                            "restart = \"never\"\nmax_restarts = \"x\""))),
    Case("launch", "args a number",
         _launch(fixtures.LAUNCH_OK.replace("restart = \"never\"",
                                            "restart = \"never\"\nargs = 5"))),
    Case("launch", "hub port 99999",
         _launch(fixtures.LAUNCH_OK.replace("auto\"", "99999\"", 1))),
    Case("launch", "hub not an endpoint",
         _launch(fixtures.LAUNCH_OK.replace("tcp/127.0.0.1:auto", "nonsense"))),
    Case("launch", "process a string", _launch("[cell]\nname = \"x\"\nprocess = \"a\"\n")),
    Case("launch", "connect a number", _launch(fixtures.LAUNCH_OK.replace(
        "hub = \"tcp/127.0.0.1:auto\"", "hub = \"tcp/127.0.0.1:auto\"\nconnect = 3"))),
    Case("launch", "heartbeat_timeout nan",
         _launch(fixtures.LAUNCH_OK.replace("heartbeat_timeout = 5.0", "heartbeat_timeout = nan"))),
    Case("launch", "params a string",
         _launch(fixtures.LAUNCH_OK.replace("[process.params]\nslice_fn = \"\"\n", "")
                 .replace("restart = \"never\"", "restart = \"never\"\nparams = \"x\""))),
    Case("launch", "cell name a table", _launch(fixtures.LAUNCH_OK.replace(
        "name = \"fuzz\"", "name = {a = 1}"))),
    Case("launch", "--set time_scale=nan", lambda tmp: [
        "launch", str(write_file(tmp / "launch.toml", fixtures.LAUNCH_OK)), "--set",
        "time_scale=nan", "--log-dir", str(tmp / "logs")]),
]


def _submit(make: Callable[[Path], Path], *extra: str) -> Callable[[Path], list[str]]:
    return lambda tmp: ["job", "submit", str(make(tmp)), *extra]


def _link(tmp: Path) -> Path:
    link = tmp / "model.stl"
    os.symlink("/etc/shadow", link)
    return link


def _link_outside(tmp: Path) -> Path:
    target = fixtures.cube_stl(tmp / "elsewhere" / "cube.stl")
    link = tmp / "imports" / "model.stl"
    link.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(target, link)
    return link


SUBMIT_CASES = [
    Case("submit", ".off model", _submit(lambda t: write_file(t / "a.off", "OFF\n3 1 0\n0 0 0\n"
                                                          "1 0 0\n0 1 0\n3 0 1 2\n"))),
    Case("submit", ".3mf model", _submit(lambda t: write_file(t / "a.3mf", b"PK\x03\x04x" * 10))),
    Case("submit", ".mesh model",
         _submit(lambda t: write_file(t / "a.mesh", "MeshVersionFormatted 1\n"))),
    Case("submit", ".stl symlink to /etc/shadow", _submit(_link)),
    Case("submit", ".stl symlink out of its folder", _submit(_link_outside)),
    Case("submit", "garbage .vtu",
         _submit(lambda t: write_file(t / "a.vtu", b"<?xml \x00\xff" * 5))),
    Case("submit", "garbage .stl",
         _submit(lambda t: write_file(t / "a.stl", bytes(range(256)) * 3))),
    Case("submit", "job file with nan", lambda tmp: [
        "job", "submit", str(fixtures.cube_stl(tmp / "c.stl")), "--job",
        str(write_file(tmp / "j.toml", "[slicing]\nsmoothness_weight = nan\n"))]),
    Case("submit", "cell file with nan", lambda tmp: [
        "job", "submit", str(fixtures.cube_stl(tmp / "c.stl")), "--cell",
        str(write_file(tmp / "c.toml", "[tank]\nyaw_deg = nan\n"))]),
]
