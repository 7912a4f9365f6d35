"""What the Ray tests share: the token their clusters use, and what a Ray session leaves running
and listening (read from /proc: the processes whose command line names the session's folder,
their children, and the TCP ports they listen on)."""

from __future__ import annotations

import ipaddress
import os
import secrets
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

#: The tests' Ray token, one per test process (Ray keeps the first token it read for the rest of
#: the process): given as RAY_AUTH_TOKEN, Ray writes no ~/.ray/auth_token into the home folder.
TOKEN = secrets.token_hex(16)


@contextmanager
def ray_environment() -> Iterator[None]:
    """``RAY_AUTH_TOKEN`` set to ``TOKEN`` and ``RAY_AUTH_MODE`` unset (as a user has it), both
    restored afterwards (a local ``ray.init`` sets ``RAY_AUTH_MODE=token`` in this process)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RAY_AUTH_TOKEN", TOKEN)
        patch.delenv("RAY_AUTH_MODE", raising=False)
        yield


def session_processes(folder: Path) -> set[int]:
    """Live processes whose command line names ``folder`` (a Ray session's temp folder: GCS,
    raylets, agents), and all their descendants (the workers)."""
    parents: dict[int, int] = {}
    named: set[int] = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if fields[0] != "Z":
            parents[int(entry.name)] = int(fields[1])
            if str(folder) in command:
                named.add(int(entry.name))
    found = set(named)
    while True:
        more = {pid for pid, parent in parents.items() if parent in found} - found
        if not more:
            return found
        found |= more


def listening_addresses(pids: set[int]) -> set[str]:
    """The local addresses (``127.0.0.1``, ``0.0.0.0``, ``::``...) of the TCP sockets that ``pids`` listen on."""
    inodes: set[str] = set()
    for pid in pids:
        try:
            links = [os.readlink(link) for link in Path(f"/proc/{pid}/fd").iterdir()]
        except OSError:
            continue
        inodes |= {link[8:-1] for link in links if link.startswith("socket:[")}
    addresses = set()
    for table in ("tcp", "tcp6"):
        for row in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = row.split()
            if fields[3] == "0A" and fields[9] in inodes:  # 0A: LISTEN
                addresses.add(_address(fields[1].split(":")[0]))
    return addresses


def _address(hex_address: str) -> str:
    """``0100007F`` -> ``127.0.0.1``; a 32-digit IPv6 address in /proc's word order -> its text
    (an IPv4-mapped one, ``::ffff:7f00:1``, as its IPv4 address)."""
    raw = bytes.fromhex(hex_address)
    if len(raw) == 4:
        return ".".join(str(b) for b in reversed(raw))
    address = ipaddress.IPv6Address(b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4)))
    return str(address.ipv4_mapped or address)


def wait_until_gone(folder: Path, seconds: float = 10.0) -> set[int]:
    """The processes of the session in ``folder`` still alive after up to ``seconds``."""
    deadline = time.monotonic() + seconds
    while (left := session_processes(folder)) and time.monotonic() < deadline:
        time.sleep(0.2)
    return left
