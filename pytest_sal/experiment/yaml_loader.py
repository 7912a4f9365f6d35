"""Reading an experiment config's YAML safely: the file checked (a regular file within the
size limit) before it is read, a SafeLoader that refuses duplicate keys and values YAML cannot
make, limits on size, nesting, values and alias expansion checked while the YAML is composed,
before anything is built, and error messages of one line that quote at most a few dozen
characters of a value.
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Hashable
from typing import Any

import yaml

from sal_adapters import SalError
from sal_adapters.quoting import short_repr

__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_DEPTH",
    "MAX_VALUES",
    "MAX_WRITTEN_VALUES",
    "NAME_CHARS",
    "PATH_CHARS",
    "QUOTE_CHARS",
    "ConfigError",
    "key_text",
    "one_line",
    "quote",
    "read_config_text",
    "read_yaml",
    "type_name",
]


class ConfigError(SalError, ValueError):
    """One problem in an experiment config: ``FILE: key.path: message (allowed: ...)``."""

    def __init__(self, source: str, where: str, message: str):
        self.source = source
        self.where = where
        super().__init__(f"{source}: {where}: {message}" if where else f"{source}: {message}")


#: Limits a config's YAML is checked against before anything is built: the file's size (bytes,
#: checked before it is read), how deep mappings and lists nest, and the values (scalars,
#: lists, mappings) it holds: as written, counted while composing, so a 1 MB flow list stops
#: at the limit (255 composite steps are about 2500), and once YAML aliases are expanded (a
#: "billion laughs" alias chain holds 10^9).
MAX_CONFIG_BYTES = 1_000_000
MAX_DEPTH = 32
MAX_VALUES = 100_000
MAX_WRITTEN_VALUES = 20_000
#: Characters of a value quoted in an error message, and of a key or a name that names nothing known.
QUOTE_CHARS = 80
NAME_CHARS = 40
#: Characters of a path quoted in an error message (a real path, already checked: the user needs it whole).
PATH_CHARS = 200


def type_name(value: Any) -> str:
    if value is None:
        return "null"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a mapping"}.get(
        type(value), type(value).__name__
    )


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping, and nesting deeper than
    ``MAX_DEPTH`` while it composes (before Python's recursion limit)."""

    depth = 0
    nodes = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        self.depth += 1
        self.nodes += 1
        try:
            if self.depth > MAX_DEPTH:
                raise _TooBig(f":{self.peek_event().start_mark.line + 1}", f"nested deeper than {MAX_DEPTH} levels; a config needs a few")
            if self.nodes > MAX_WRITTEN_VALUES:
                raise _TooBig(
                    f":{self.peek_event().start_mark.line + 1}",
                    f"holds more than {MAX_WRITTEN_VALUES} values; a config needs a few hundred",
                )
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        """A value YAML cannot make (``2001-02-30``, ``!!int x``, 5000 digits) is a
        ``ConstructorError`` naming its line, not the ``ValueError`` of its constructor."""
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError):
            tag = node.tag.rsplit(":", 1)[-1]
            raise yaml.constructor.ConstructorError(
                None, None, f"{quote(node.value)} is not a valid {tag} value", node.start_mark
            ) from None


def _construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
    seen: dict[Any, int] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if not isinstance(key, Hashable):
            raise yaml.constructor.ConstructorError(None, None, f"a key cannot be {type_name(key)}", key_node.start_mark)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {quote(key)} appears twice (first on line {seen[key] + 1})", key_node.start_mark
            )
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


class _TooBig(Exception):
    """A config over one of the limits (``where`` names the line)."""

    def __init__(self, where: str, message: str):
        super().__init__(message)
        self.where = where


def _check_size(node: yaml.Node) -> None:
    """Refuse nesting deeper than ``MAX_DEPTH`` and more than ``MAX_VALUES`` values once
    aliases are expanded, counted on the composed node graph (shared nodes counted once per
    use, each node visited once)."""
    expanded: dict[int, int] = {}

    def count(n: yaml.Node, depth: int) -> int:
        if depth > MAX_DEPTH:
            raise _TooBig(f":{n.start_mark.line + 1}", f"nested deeper than {MAX_DEPTH} levels; a config needs a few")
        if id(n) in expanded:
            return expanded[id(n)]
        children: list[yaml.Node] = []
        if isinstance(n, yaml.MappingNode):
            children = [c for pair in n.value for c in pair]
        elif isinstance(n, yaml.SequenceNode):
            children = list(n.value)
        total = 1 + sum(count(c, depth + 1) for c in children)
        if total > MAX_VALUES:
            raise _TooBig(
                f":{n.start_mark.line + 1}",
                f"holds more than {MAX_VALUES} values once its YAML aliases are expanded; a config needs a few hundred",
            )
        expanded[id(n)] = total
        return total

    count(node, 0)


def quote(value: Any, limit: int = QUOTE_CHARS) -> str:
    """``repr(value)``, cut to ``limit`` characters (errors quote, they do not dump)."""
    return short_repr(value, limit)


_KEY = re.compile(rf"[A-Za-z0-9_.-]{{1,{NAME_CHARS}}}")


def key_text(key: Any) -> str:
    """A key of the config as its path shows it: a plain word as it is, anything else quoted."""
    return key if isinstance(key, str) and _KEY.fullmatch(key) else quote(key, NAME_CHARS)


def one_line(text: str, limit: int = 2 * QUOTE_CHARS) -> str:
    """``text`` as one printable line (other characters escaped) of at most ``limit`` characters."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:limit])
    return text if len(text) <= limit else text[: limit - 3] + "..."


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
        raise ConfigError(source, "", f"cannot read the config: {exc}") from None


def _file_kind(mode: int) -> str:
    """What a file of ``mode`` is, in words (``a folder``, ``a FIFO``)."""
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))
    return next((words for test, words in kinds if test(mode)), "a socket" if stat.S_ISSOCK(mode) else "not a file")


def read_yaml(text: str, source: str = "<config>") -> Any:
    """The data of the YAML ``text`` (``source`` names it in errors), loaded safely within the
    limits above; any problem is one ``ConfigError`` line naming the line of the file."""
    if len(text.encode("utf-8", "replace")) > MAX_CONFIG_BYTES:
        raise ConfigError(source, "", f"the config is {len(text.encode('utf-8', 'replace'))} bytes; the limit is {MAX_CONFIG_BYTES} bytes")
    try:
        loader = _UniqueKeyLoader(text)  # a SafeLoader subclass
        try:
            node = loader.get_single_node()
            if node is not None:
                _check_size(node)
            data = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except _TooBig as exc:
        raise ConfigError(f"{source}{exc.where}", "", str(exc)) from None
    except RecursionError:
        raise ConfigError(source, "", f"nested deeper than {MAX_DEPTH} levels; a config needs a few") from None
    except yaml.reader.ReaderError as exc:  # str() of it is three lines
        line = text.count("\n", 0, exc.position) + 1
        raise ConfigError(
            f"{source}:{line}", "", f"YAML syntax error: character #x{exc.character:04x} is not allowed ({exc.reason})"
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        at_line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError(f"{source}{at_line}", "", f"YAML syntax error: {one_line(problem)}") from None
    return data
