"""The Dockerfile's base image (``python:3.11-slim``) in the local engine: pulled, or, where no image registry
can be reached, a stand-in made from Debian's packages with mmdebstrap.

Standard library only, so that ``.ci/run`` can provision it before the tests, as a machine with a registry
would pull it once and keep it in the engine's cache (``python3 tests/compose/base_image.py``); the compose
test calls the same ``ensure_base_image`` and makes it itself where it is missing."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

BASE_IMAGE = "python:3.11-slim"  # the Dockerfile's FROM
STAND_IN_LABEL = "org.petswarm.stand-in"
STAND_IN_SUITE = "bookworm"  # Debian 12: its python3 is 3.11, as in the real image


class BaseImageUnavailable(RuntimeError):
    """The base image is not in the engine and cannot be pulled nor made here (the message says why)."""


def run(argv: Sequence[str], timeout: float, check: bool = False, **kw: object) -> subprocess.CompletedProcess[str]:
    """Run a command; a timeout is a failure that says which command hung."""
    try:
        done = subprocess.run(list(argv), capture_output=True, text=True, timeout=timeout, **kw)  # type: ignore[call-overload]
    except subprocess.TimeoutExpired as err:
        raise AssertionError(
            f"{' '.join(argv)} did not finish within {timeout} s:\n{err.stdout}\n{err.stderr}"
        ) from None
    if check and done.returncode != 0:
        raise AssertionError(
            f"{' '.join(argv)} exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        )
    return done


def image_exists(ref: str) -> bool:
    """Whether the engine has the image ``ref``."""
    return run(["docker", "image", "inspect", ref], 60).returncode == 0


def ensure_base_image(workdir: Path) -> str | None:
    """The base image: already here (None), pulled ("pulled"), or a stand-in made here ("stand-in"): Debian 12
    with python3 and pip, bootstrapped by mmdebstrap (a minute or two; debootstrap takes twice the CPU) and
    imported under the same name. Returns what it added. Raises BaseImageUnavailable."""
    if image_exists(BASE_IMAGE):
        return None
    pulled = run(["docker", "pull", BASE_IMAGE], 300)
    if pulled.returncode == 0:
        return "pulled"
    if shutil.which("mmdebstrap") is None or os.geteuid() != 0:
        raise BaseImageUnavailable(
            f"{BASE_IMAGE} cannot be pulled ({pulled.stderr.strip()}) nor made here (needs mmdebstrap, root)"
        )
    tarball = workdir / "stand-in.tar"
    try:
        made = run(_mmdebstrap_argv(tarball), 900)
        # a failure to make it where it can be made is a failure, not a missing prerequisite
        assert made.returncode == 0, f"mmdebstrap of the stand-in base image failed:\n{made.stderr[-3000:]}"
        changes = ["ENV LANG=C.UTF-8", 'CMD ["python3"]', f"LABEL {STAND_IN_LABEL}=mmdebstrap-{STAND_IN_SUITE}"]
        run(["docker", "import", *(a for c in changes for a in ("--change", c)), str(tarball), BASE_IMAGE], 300, True)
    finally:
        tarball.unlink(missing_ok=True)
    return "stand-in"


def _mmdebstrap_argv(tarball: Path) -> list[str]:
    slim = [f"--dpkgopt=path-exclude=/usr/share/{d}/*" for d in ("doc", "man", "locale", "info")]  # as slim images
    hooks = [
        'rm -f "$1"/usr/lib/python3*/EXTERNALLY-MANAGED',  # its pip installs into the system Python, as in the image
        'ln -sf python3 "$1"/usr/bin/python',
        'ln -sf pip3 "$1"/usr/bin/pip',
    ]
    if Path("/etc/ssl/certs/ca-certificates.crt").exists():  # the host's trust, for the build's pip
        hooks.append("copy-in /etc/ssl/certs/ca-certificates.crt /etc/ssl/certs")
    return [
        "mmdebstrap",
        "--variant=minbase",
        "--include=python3,python3-venv,python3-pip,ca-certificates",
        *slim,
        *(f"--customize-hook={hook}" for hook in hooks),
        STAND_IN_SUITE,
        str(tarball),
        debian_mirror(),
    ]


def debian_mirror() -> str:
    """The Debian archive apt is configured with here (read from apt, never written down in the repository)."""
    listed = run(["apt-get", "indextargets", "--format", "$(REPO_URI) $(RELEASE) $(IDENTIFIER)"], 30, check=True)
    rows = [line.split() for line in listed.stdout.splitlines() if len(line.split()) == 3]
    codename = ""
    if Path("/etc/os-release").exists():
        found = re.search(r"^VERSION_CODENAME=(\S+)", Path("/etc/os-release").read_text(), re.M)
        codename = found.group(1) if found else ""
    for release in (STAND_IN_SUITE, codename):  # an archive that lists the host's release has bookworm as well
        for uri, rel, ident in rows:
            if rel == release and ident == "Packages":
                return uri
    raise BaseImageUnavailable(f"no Debian archive in apt's sources to make the stand-in {BASE_IMAGE} from")


def main() -> int:
    """Provision the base image (``.ci/run``); prints what it did and how long it took."""
    started = time.monotonic()
    try:
        with tempfile.TemporaryDirectory() as work:
            added = ensure_base_image(Path(work))
    except (BaseImageUnavailable, AssertionError) as err:
        print(f"base image: {err}", file=sys.stderr)
        return 1
    print(f"base image {BASE_IMAGE}: {added or 'present'} ({time.monotonic() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
