"""``petswarm certs``: a CA and the certificates of a hub, its robots, users and an operator (openssl CLI).

A certificate's common name is its role in the hub's access control (radio_hub/link/trust.py): ``hub``,
``robot-<n>``, ``user-<n>``, ``operator``. The hub's certificate names the hosts clients dial, since a client
checks the name in the endpoint against it. Keys are written 0600 in a 0700 directory.
"""

from __future__ import annotations

import ipaddress
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from radio_hub.interface import OPERATOR

DAYS = 30


@dataclass
class CertsOptions:
    """What ``petswarm certs`` takes."""

    out: str
    """Directory for the PEM files (created 0700)."""
    hub_host: str
    """Names or IP addresses clients dial the hub by, comma-separated."""
    robots: int = 4
    """Certificates robot-1..robot-N."""
    users: int = 1
    """Certificates user-1..user-N."""


def certs_command(args: CertsOptions) -> int:
    """Write ca.pem, and NAME.pem with NAME.key for the hub, every robot, every user and the operator."""
    if shutil.which("openssl") is None:
        print("petswarm certs: the openssl command is needed", file=sys.stderr)
        return 2
    names = [f"robot-{n}" for n in range(1, args.robots + 1)] + [f"user-{n}" for n in range(1, args.users + 1)]
    try:
        make_certificates(Path(args.out), args.hub_host.split(","), [*names, OPERATOR])
    except (OSError, subprocess.CalledProcessError) as err:
        print(f"petswarm certs: {err}", file=sys.stderr)
        return 1
    print(f"certs: CA, hub and {len(names) + 1} client certificates in {args.out}")
    return 0


def make_certificates(out: Path, hub_hosts: list[str], clients: list[str]) -> None:
    """A fresh CA in ``out`` signing the hub's certificate (for ``hub_hosts``) and one per client name."""
    out.mkdir(parents=True, exist_ok=True)
    out.chmod(0o700)
    _openssl("req", "-x509", *_new_key(out / "ca.key"), "-out", str(out / "ca.pem"), "-subj", "/CN=petswarm-ca")
    _sign(out, "hub", [_alt_name(h) for h in hub_hosts if h])
    for name in clients:
        _sign(out, name, [f"DNS:{name}"])
    for key in out.glob("*.key"):
        key.chmod(0o600)


def _alt_name(host: str) -> str:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return f"DNS:{host}"
    return f"IP:{host}"


def _new_key(path: Path) -> list[str]:
    return ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", str(path)]


def _sign(out: Path, name: str, alt_names: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        csr, ext = Path(tmp, "req.csr"), Path(tmp, "ext.cnf")
        _openssl("req", *_new_key(out / f"{name}.key"), "-out", str(csr), "-subj", f"/CN={name}")
        ext.write_text(f"subjectAltName={','.join(alt_names)}\n")
        _openssl(
            "x509", "-req", "-in", str(csr), "-CA", str(out / "ca.pem"), "-CAkey", str(out / "ca.key"),
            "-CAcreateserial", "-out", str(out / f"{name}.pem"), "-days", str(DAYS), "-extfile", str(ext),
        )  # fmt: skip


def _openssl(*args: str) -> None:
    # openssl reports progress on stderr: shown only when it fails
    done = subprocess.run(["openssl", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise subprocess.CalledProcessError(done.returncode, "openssl " + args[0], stderr=done.stderr)
