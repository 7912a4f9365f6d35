"""Reading an experiment config's YAML safely: the file checked (a regular file within the
size limit) before it is read, then the bounded loader of ``sal_adapters.common.bounded_yaml``
(duplicate keys, values YAML cannot make, size, nesting, values as written and after alias
expansion refused while the YAML is composed, before anything is built), and the one-line
``ConfigError`` it reports.
"""

from __future__ import annotations

import os
import re
import stat
from typing import Any

from sal_adapters import SalError
from sal_adapters.common.bounded_yaml import YamlError, YamlLimits, load_yaml, quote

__all__ = [
    "CONFIG_YAML",
    "MAX_CONFIG_BYTES",
    "NAME_CHARS",
    "PATH_CHARS",
    "ConfigError",
    "key_text",
    "read_config_text",
    "read_yaml",
]


class ConfigError(SalError, ValueError):
    """One problem in an experiment config: ``FILE: key.path: message (allowed: ...)``."""

    def __init__(self, source: str, where: str, message: str):
        self.source = source
        self.where = where
        super().__init__(f"{source}: {where}: {message}" if where else f"{source}: {message}")


#: Largest config file (bytes), checked before it is read. Its nesting and expanded values are
#: limited as every YAML's, and it holds at most 20 000 values as written, counted while it is
#: composed, so a 1 MB flow list stops at the limit (255 composite steps are about 2500).
MAX_CONFIG_BYTES = 1_000_000
CONFIG_YAML = YamlLimits(max_bytes=MAX_CONFIG_BYTES, what="a config", max_written_values=20_000)
#: Characters of a key or a name that names nothing known, quoted in an error message.
NAME_CHARS = 40
#: Characters of a path quoted in an error message (a real path, already checked: the user needs it whole).
PATH_CHARS = 200


_KEY = re.compile(rf"[A-Za-z0-9_.-]{{1,{NAME_CHARS}}}")


def key_text(key: Any) -> str:
    """A key of the config as its path shows it: a plain word as it is, anything else quoted."""
    return key if isinstance(key, str) and _KEY.fullmatch(key) else quote(key, NAME_CHARS)


def read_yaml(text: str, source: str = "<config>") -> Any:
    """The data of the YAML ``text`` (``source`` names it in errors), loaded within
    ``CONFIG_YAML``; any problem is one ``ConfigError`` line naming the line of the file."""
    try:
        return load_yaml(text, source, CONFIG_YAML).data
    except YamlError as exc:
        raise ConfigError(exc.source if exc.line is None else f"{exc.source}:{exc.line}", "", exc.problem) from None


def read_config_text(path: str | os.PathLike[str]) -> str:
    """The UTF-8 text of the config file at ``path``, checked before it is read: a regular file
    (not a FIFO, a device such as ``/dev/zero``, a folder) of at most ``MAX_CONFIG_BYTES``
    bytes; at most that many bytes (and one) are read, should it grow meanwhile. Any problem is
    one ``ConfigError`` naming the file."""
    source = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # O_NONBLOCK: a FIFO without writer opens
    except FileNotFoundError:
        raise ConfigError(source, "", "config file not found") from None
    except OSError as exc:
        raise ConfigError(source, "", f"cannot read the config: {exc.strerror}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(source, "", f"is {_file_kind(info.st_mode)}, not a regular file; give the config's YAML file")
        if info.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(source, "", f"the config is {info.st_size} bytes; the limit is {MAX_CONFIG_BYTES} bytes")
        data = os.read(fd, MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(source, "", f"cannot read the config: {exc.strerror}") from None
    finally:
        os.close(fd)
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(
            source, "", f"the config grew past {MAX_CONFIG_BYTES} bytes while it was read; the limit is {MAX_CONFIG_BYTES} bytes"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(source, "", f"cannot read the config: not UTF-8 text: byte {exc.start} is not valid") from None


def _file_kind(mode: int) -> str:
    """What a file of ``mode`` is, in words (``a folder``, ``a FIFO``)."""
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))
    return next((words for test, words in kinds if test(mode)), "a socket" if stat.S_ISSOCK(mode) else "not a file")
