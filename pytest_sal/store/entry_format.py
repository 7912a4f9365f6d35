"""The bytes of a cache entry and how they check themselves.

A result entry is ``{"sha256": ..., "key": ..., "data": {...}}``: the key it was stored under,
and the checksum of the canonical JSON (keys sorted, compact, UTF-8 kept) of ``{"data": ...,
"key": ...}``. The checksum covers the key, so an entry proves which key it belongs to: a valid
entry of another trial copied under this key is refused like a damaged one. A folder entry holds
its files in ``data/`` and, written last, ``manifest.json``: such an entry whose data lists each
file's size and SHA-256 (``{"files": {relative path: [bytes, sha256]}}``).

These encodings are the stored format: changing them turns every stored entry into a bad one
(removed and computed again). Entries of the format before keys (``{"sha256", "data"}``, until
issue 23) are such entries: they name no key, so nothing shows that they belong to theirs.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["FILES", "MANIFEST", "file_listing", "listing_mismatch", "pack_entry", "unpack_entry"]

#: A folder entry's manifest file, and its folder of files (what ``compute_dir`` returns).
MANIFEST = "manifest.json"
FILES = "data"


def pack_entry(key: str, data: Mapping[str, Any]) -> bytes:
    """The bytes of the entry of ``key`` holding ``data``: ``{"sha256": <of the canonical JSON of
    key and data>, "key": key, "data": ...}``.

    Raises:
        TypeError, ValueError: ``data`` is not JSON-ready.
    """
    payload = _canonical(data)
    return f'{{"sha256":"{_sha256(_signed(key, payload))}","key":{json.dumps(key, ensure_ascii=False)},"data":{payload}}}\n'.encode()


def unpack_entry(raw: bytes, key: str) -> tuple[dict[str, Any] | None, str | None]:
    """``(data, None)`` of the bytes of ``key``'s entry, or ``(None, what is wrong)`` in a few words."""
    try:
        entry = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        return None, f"not UTF-8 (byte 0x{raw[exc.start]:02x} at offset {exc.start})"
    except ValueError as exc:
        return None, f"not JSON ({exc})" if raw.strip() else "empty"
    if isinstance(entry, dict) and set(entry) == {"sha256", "data"}:
        return None, "names no key (written before pytest-sal entries named their key, so nothing shows it belongs to this one)"
    if not isinstance(entry, dict) or set(entry) != {"sha256", "key", "data"}:
        shape = f"keys {', '.join(sorted(entry)[:5]) or '(none)'}" if isinstance(entry, dict) else f"a JSON {type(entry).__name__}"
        return None, f"no checksum: {shape}, not sha256, key and data (written by hand, or before pytest-sal checked its entries)"
    if not isinstance(entry["data"], dict):
        return None, f"its data is a JSON {type(entry['data']).__name__}, not an object"
    if not isinstance(entry["key"], str) or _sha256(_signed(entry["key"], _canonical(entry["data"]))) != entry["sha256"]:
        return None, "checksum mismatch: changed after it was written"
    if entry["key"] != key:
        return None, f"it is the entry of key {entry['key'][:12]}..., not of {key[:12]}... (copied from another entry)"
    return entry["data"], None


def file_listing(folder: Path, hashes: bool) -> dict[str, list[Any]]:
    """``{relative path: [size in bytes, SHA-256 or None]}`` of every file under ``folder``
    (the SHA-256 only when ``hashes``)."""
    out: dict[str, list[Any]] = {}
    for base, _dirs, names in os.walk(folder):
        for name in names:
            path = os.path.join(base, name)
            out[os.path.relpath(path, folder)] = [os.stat(path).st_size, _file_sha256(path) if hashes else None]
    return out


def listing_mismatch(listed: Any, found: dict[str, list[Any]]) -> str | None:
    """How the files ``found`` (``file_listing``) differ from a manifest's ``listed`` files, in
    words, or ``None`` when they match (a ``None`` hash in ``found`` is not compared)."""
    if not isinstance(listed, dict) or not all(isinstance(v, list) and len(v) == 2 for v in listed.values()):
        return f"{MANIFEST} lists no files"
    for name in sorted(set(listed) | set(found)):
        if name not in found:
            return f"{FILES}/{name} is missing"
        if name not in listed:
            return f"{FILES}/{name} is not in {MANIFEST}"
        (size, digest), (real_size, real_digest) = listed[name], found[name]
        if real_size != size:
            return f"{FILES}/{name} has {real_size} bytes, {MANIFEST} says {size}"
        if real_digest is not None and real_digest != digest:
            return f"{FILES}/{name}: content differs from its SHA-256 in {MANIFEST}"
    return None


def _canonical(data: Mapping[str, Any]) -> str:
    """The JSON text an entry's checksum covers: keys sorted, compact, UTF-8 kept."""
    return json.dumps(dict(data), sort_keys=True, separators=(",", ":"), ensure_ascii=False)


def _signed(key: str, payload: str) -> str:
    """What an entry's checksum covers: the canonical JSON of ``{"data": ..., "key": key}``,
    ``payload`` being the canonical JSON of its data."""
    return f'{{"data":{payload},"key":{json.dumps(key, ensure_ascii=False)}}}'


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _file_sha256(path: str) -> str:
    with open(path, "rb") as handle:
        return hashlib.file_digest(handle, "sha256").hexdigest()
