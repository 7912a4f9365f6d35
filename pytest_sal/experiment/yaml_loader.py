"""Reading an experiment config's YAML safely, through the bounded loader of
``sal_adapters.bounded_yaml`` (duplicate keys, values YAML cannot make, size, nesting and alias
expansion refused before anything is built), and the one-line ``ConfigError`` it reports.
"""

from __future__ import annotations

import re
from typing import Any

from sal_adapters import SalError
from sal_adapters.bounded_yaml import YamlError, YamlLimits, load_yaml, quote

__all__ = [
    "CONFIG_YAML",
    "MAX_CONFIG_BYTES",
    "NAME_CHARS",
    "PATH_CHARS",
    "ConfigError",
    "key_text",
    "read_yaml",
]


class ConfigError(SalError, ValueError):
    """One problem in an experiment config: ``FILE: key.path: message (allowed: ...)``."""

    def __init__(self, source: str, where: str, message: str):
        self.source = source
        self.where = where
        super().__init__(f"{source}: {where}: {message}" if where else f"{source}: {message}")


#: Largest config file (bytes); its nesting and expanded values are limited as every YAML's.
MAX_CONFIG_BYTES = 1_000_000
CONFIG_YAML = YamlLimits(max_bytes=MAX_CONFIG_BYTES, what="a config")
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
