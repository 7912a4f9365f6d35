"""Reading an experiment config's YAML safely: a SafeLoader that refuses duplicate keys and
values YAML cannot make, limits on size, nesting and alias expansion checked before anything is
built, and error messages of one line that quote at most a few dozen characters of a value.
"""

from __future__ import annotations

import re
import reprlib
from collections.abc import Hashable
from typing import Any

import yaml

from sal_adapters import SalError

__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_DEPTH",
    "MAX_VALUES",
    "NAME_CHARS",
    "PATH_CHARS",
    "QUOTE_CHARS",
    "ConfigError",
    "key_text",
    "one_line",
    "quote",
    "read_yaml",
    "type_name",
]


class ConfigError(SalError, ValueError):
    """One problem in an experiment config: ``FILE: key.path: message (allowed: ...)``."""

    def __init__(self, source: str, where: str, message: str):
        self.source = source
        self.where = where
        super().__init__(f"{source}: {where}: {message}" if where else f"{source}: {message}")


#: Limits a config's YAML is checked against before anything is built: the file's size, how
#: deep mappings and lists nest, and the values it holds once YAML aliases are expanded (a
#: "billion laughs" alias chain holds 10^9).
MAX_CONFIG_BYTES = 1_000_000
MAX_DEPTH = 32
MAX_VALUES = 100_000
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

    def compose_node(self, parent: Any, index: Any) -> Any:
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise _TooBig(f":{self.peek_event().start_mark.line + 1}", f"nested deeper than {MAX_DEPTH} levels; a config needs a few")
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
    text = reprlib.repr(value) if isinstance(value, (dict, list, tuple, set)) else repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


_KEY = re.compile(rf"[A-Za-z0-9_.-]{{1,{NAME_CHARS}}}")


def key_text(key: Any) -> str:
    """A key of the config as its path shows it: a plain word as it is, anything else quoted."""
    return key if isinstance(key, str) and _KEY.fullmatch(key) else quote(key, NAME_CHARS)


def one_line(text: str, limit: int = 2 * QUOTE_CHARS) -> str:
    """``text`` as one printable line (other characters escaped) of at most ``limit`` characters."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:limit])
    return text if len(text) <= limit else text[: limit - 3] + "..."


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
