"""Zenoh TLS and access control for a cell that spans hosts.

On one host every listener binds 127.0.0.1 and the cell's secret (``signing``) proves who sent
what. Across hosts the links must also be private and only the cell's machines may join: each
process then gets a TLS folder (``BusConfig.tls_dir``, or ``$MESP_BUS_TLS`` for every process
a launcher starts) holding

* ``ca.pem``: the cell's certificate authority (only certificates it signed may connect);
* ``cert.pem``, ``key.pem``: this host's certificate (its subject alternative names the host's
  address) and key; used both to listen and to connect (mutual TLS);
* ``acl.json5`` (optional): zenoh's ``access_control`` table, applied to what the peers
  connected over TLS may send and receive, by their certificate's common name.

Endpoints are then written ``tls/HOST:PORT``. See docs/security.md for making the files.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from core.errors import InputError

FILES = ("ca.pem", "cert.pem", "key.pem")


def tls_folder(configured: str) -> Path | None:
    """The TLS folder in effect: ``configured``, else ``$MESP_BUS_TLS``, else None."""
    path = configured or os.environ.get("MESP_BUS_TLS", "")
    return Path(path) if path else None


def apply_tls(zc: Any, folder: Path) -> None:
    """Insert TLS (mutual, names verified) and the folder's access control into a zenoh
    config; a missing file is a one-line ``InputError``."""
    for name in FILES:
        if not (folder / name).is_file():
            raise InputError(f"the bus TLS folder {folder} has no {name}",
                             "make the cell's certificates as docs/security.md shows")
    ca, cert, key = (str((folder / n).resolve()) for n in FILES)
    tls = {"root_ca_certificate": ca, "listen_certificate": cert, "listen_private_key": key,
           "connect_certificate": cert, "connect_private_key": key, "enable_mtls": True,
           "verify_name_on_connect": True}
    zc.insert_json5("transport/link/tls", json.dumps(tls))
    acl = folder / "acl.json5"
    if acl.is_file():
        zc.insert_json5("access_control", acl.read_text())
