"""A cell across hosts: zenoh TLS (mutual, names verified) and access control, on loopback with
certificates made here by the openssl CLI. A peer with the cell's certificate talks; one with
a certificate of another authority, or none, hears nothing; a certificate whose name the access
control makes read-only can listen but not command."""

from __future__ import annotations

import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.bus.signing import Role
from mesp_cell.drivers.extruder_emulator import free_port
from mesp_cell.messages import Command, Heartbeat, Reply

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl CLI")
KEY = b"s" * 32
ACL = """{
  enabled: true,
  default_permission: "deny",
  rules: [
    {id: "all", permission: "allow", flows: ["ingress", "egress"],
     messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"],
     key_exprs: ["mesp/**"]},
    {id: "read", permission: "allow", flows: ["ingress", "egress"],
     messages: ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
     key_exprs: ["mesp/**"]},
    {id: "read-in", permission: "allow", flows: ["egress"], messages: ["put"],
     key_exprs: ["mesp/**"]},
  ],
  subjects: [{id: "nodes", cert_common_names: ["mesp-node"]},
             {id: "viewers", cert_common_names: ["mesp-viewer"]}],
  policies: [{rules: ["all"], subjects: ["nodes"]},
             {rules: ["read", "read-in"], subjects: ["viewers"]}],
}
"""


def openssl(*args: str | Path) -> None:
    subprocess.run(["openssl", *map(str, args)], check=True, capture_output=True)


def make_ca(folder: Path, name: str) -> tuple[Path, Path]:
    folder.mkdir(parents=True, exist_ok=True)
    key, cert = folder / f"{name}-ca.key", folder / f"{name}-ca.pem"
    openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
            "-keyout", key, "-out", cert, "-days", "2", "-subj", f"/CN={name} CA")
    return key, cert


def make_host(folder: Path, ca: tuple[Path, Path], cn: str, acl: str = "") -> Path:
    """A TLS folder (``bus.tls``) with a certificate for 127.0.0.1 signed by ``ca``."""
    folder.mkdir(parents=True)
    ext = folder / "ext.cnf"
    ext.write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n"
                   "extendedKeyUsage=serverAuth,clientAuth\n")
    openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
            "-keyout", folder / "key.pem", "-out", folder / "req.csr", "-subj", f"/CN={cn}")
    openssl("x509", "-req", "-in", folder / "req.csr", "-CA", ca[1], "-CAkey", ca[0],
            "-CAcreateserial", "-out", folder / "cert.pem", "-days", "2", "-extfile", ext)
    shutil.copy(ca[1], folder / "ca.pem")
    if acl:
        (folder / "acl.json5").write_text(acl)
    return folder


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("pki")
    cell = make_ca(root / "ca", "cell")
    other = make_ca(root / "other", "other")
    return {"hub": make_host(root / "hub", cell, "mesp-node", ACL),
            "node": make_host(root / "node", cell, "mesp-node"),
            "viewer": make_host(root / "viewer", cell, "mesp-viewer"),
            "stranger": make_host(root / "stranger", other, "mesp-node")}


@pytest.fixture
def hub(pki: dict[str, Path]) -> Iterator[tuple[Bus, str]]:
    ep = f"tls/127.0.0.1:{free_port()}"
    bus = Bus(BusConfig(cell="t", listen=(ep,), tls_dir=str(pki["hub"])), "alpha",
              Role.NODE, KEY)
    bus.serve(lambda cmd: Reply.done(echo=cmd.verb))
    yield bus, ep
    bus.close()


def peer(pki: dict[str, Path], who: str, ep: str, name: str) -> Bus:
    """A session on ``ep`` with ``who``'s certificate (it connects in the background: a test
    waits for what it needs, ``wait_served`` or ``wait_subscribed``)."""
    return Bus(BusConfig(cell="t", listen=("tls/127.0.0.1:0",), connect=(ep,),
                         tls_dir=str(pki[who])), name, Role.OPERATOR, KEY)


#: the beats' topic: one that waits for room (on a periodic topic such as "heartbeat" a loaded
#: host's congested link may drop a beat, which the next one supersedes); the access control
#: covers every key under mesp/** alike
BEATS = "beats"


def beats_heard(listener: Bus, sender: Bus, n: int = 5, patience: float = 10.0) -> int:
    """How many of ``n`` heartbeats ``sender`` publishes ``listener`` hears. The sender waits
    for the subscription to reach it, then the beats are waited for, each wait ``patience`` s
    at most (a short one where nothing should arrive: those beats go out after it anyway)."""
    got: list[Heartbeat] = []
    lock = threading.Lock()

    def on(m: Heartbeat) -> None:
        with lock:
            got.append(m)

    listener.subscribe(sender.node, BEATS, Heartbeat, on)
    sender.wait_subscribed(BEATS, timeout=patience)
    for i in range(n):
        sender.publish(BEATS, Heartbeat(sender.node, "active", i, 1, time.time()))
    end = time.monotonic() + patience
    while time.monotonic() < end:
        with lock:
            if len(got) >= n:
                break
        time.sleep(0.02)
    with lock:
        return len(got)


def test_a_peer_with_the_cells_certificate_talks(pki: dict[str, Path],
                                                 hub: tuple[Bus, str]) -> None:
    alpha, ep = hub
    node = peer(pki, "node", ep, "beta")
    try:
        assert node.wait_served("alpha", timeout=10.0)
        assert node.request("alpha", Command.make("ping"), 5.0).value("echo") == "ping"
        assert beats_heard(alpha, node) == 5
        assert beats_heard(node, alpha) == 5
    finally:
        node.close()


def test_a_peer_of_another_authority_hears_nothing(pki: dict[str, Path],
                                                   hub: tuple[Bus, str]) -> None:
    alpha, ep = hub
    stranger = peer(pki, "stranger", ep, "beta")
    try:
        assert not stranger.wait_served("alpha", timeout=1.0)  # time to try the handshake
        r = stranger.request("alpha", Command.make("ping"), 2.0)
        assert not r.ok and "no reply" in r.reason
        assert beats_heard(stranger, alpha, patience=1.0) == 0
    finally:
        stranger.close()
    plain = Bus(BusConfig(cell="t", connect=(ep.replace("tls/", "tcp/"),)), "gamma",
                Role.OPERATOR, KEY)
    try:
        assert not plain.wait_served("alpha", timeout=1.0)
        r = plain.request("alpha", Command.make("ping"), 2.0)
        assert not r.ok and "no reply" in r.reason
    finally:
        plain.close()


def test_access_control_makes_a_viewer_read_only(pki: dict[str, Path],
                                                 hub: tuple[Bus, str]) -> None:
    alpha, ep = hub
    viewer = peer(pki, "viewer", ep, "viewer")
    try:
        assert beats_heard(viewer, alpha) == 5  # it may listen
        assert beats_heard(alpha, viewer, patience=1.0) == 0  # it may not publish
        r = viewer.request("alpha", Command.make("ping"), 2.0)  # nor command
        assert not r.ok and "no reply" in r.reason
    finally:
        viewer.close()


def test_a_missing_certificate_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"has no ca\.pem"):
        Bus(BusConfig(cell="t", listen=("tls/127.0.0.1:0",), tls_dir=str(tmp_path)), "x",
            Role.NODE, KEY)
