"""Reading YAML safely, for experiment configs and dataset files alike (issue 12's loader):
a SafeLoader that refuses duplicate keys and values YAML cannot make, limits on size, nesting
and alias expansion checked before anything is built, and error messages of one line that
quote at most a few dozen characters of a value.

``load_yaml`` raises ``YamlError`` (file, line, problem); the experiment config turns it into
its ``ConfigError``, the dataset readers (``read_dataset_yaml``) into a ``DatasetError``.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from sal_adapters.common.errors import DatasetError, SalError
from sal_adapters.common.quoting import short_repr
from sal_adapters.common.textfiles import read_text

__all__ = [
    "DATASET_YAML",
    "QUOTE_CHARS",
    "YamlDocument",
    "YamlError",
    "YamlLimits",
    "load_yaml",
    "one_line",
    "quote",
    "read_dataset_yaml",
    "type_name",
]

#: Characters of a value quoted in an error message.
QUOTE_CHARS = 80


@dataclass(frozen=True)
class YamlLimits:
    """What a YAML file is checked against before anything is built: its size (bytes), how deep
    mappings and lists nest, the values it holds once aliases are expanded (a "billion laughs"
    alias chain holds 10^9) and, when given, as written (counted while it is composed, so a
    long flow list stops at the limit); ``what`` names the file in messages (``a config``)."""

    max_bytes: int
    what: str
    max_depth: int = 32
    max_values: int = 100_000
    max_written_values: int | None = None


#: Limits of a dataset's YAML (EuRoC ``sensor.yaml``, a folder's ``camera.yaml``): a real one
#: is about 1 kB and holds a few dozen values.
DATASET_YAML = YamlLimits(max_bytes=100_000, what="a dataset YAML file", max_values=10_000)


class YamlError(SalError, ValueError):
    """A YAML text over a limit or not valid YAML: ``SOURCE:LINE: problem``."""

    def __init__(self, source: str, line: int | None, problem: str):
        self.source, self.line, self.problem = source, line, problem
        super().__init__(f"{source}:{line}: {problem}" if line is not None else f"{source}: {problem}")


@dataclass(frozen=True)
class YamlDocument:
    """The data of a YAML text, and the line (1-based) of each key of its top-level mapping."""

    data: Any
    key_lines: dict[str, int] = field(default_factory=dict)


def type_name(value: Any) -> str:
    """``a string``, ``a list``, ``null``: the YAML type of ``value`` for messages."""
    if value is None:
        return "null"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "a list", dict: "a mapping"}.get(
        type(value), type(value).__name__
    )


def quote(value: Any, limit: int = QUOTE_CHARS) -> str:
    """``repr(value)``, cut to ``limit`` characters (errors quote, they do not dump; an integer
    of thousands of digits is shown by its number of digits)."""
    return short_repr(value, limit)


def one_line(text: str, limit: int = 2 * QUOTE_CHARS) -> str:
    """``text`` as one printable line (other characters escaped) of at most ``limit`` characters."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:limit])
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _TooBig(Exception):
    """A YAML text over one of the limits, at ``line``."""

    def __init__(self, line: int | None, message: str):
        super().__init__(message)
        self.line = line


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping, and nesting deeper than
    ``limits.max_depth`` or more values than ``limits.max_written_values`` while it composes
    (before Python's recursion limit, before a long list is built)."""

    depth = 0
    nodes = 0

    def __init__(self, text: str, limits: YamlLimits):
        super().__init__(text)
        self.limits = limits

    def compose_node(self, parent: Any, index: Any) -> Any:
        self.depth += 1
        self.nodes += 1
        try:
            if self.depth > self.limits.max_depth:
                raise _TooBig(self.peek_event().start_mark.line + 1, _too_deep(self.limits))
            written = self.limits.max_written_values
            if written is not None and self.nodes > written:
                raise _TooBig(
                    self.peek_event().start_mark.line + 1, f"holds more than {written} values; {self.limits.what} needs a few hundred"
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


_BoundedLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _too_deep(limits: YamlLimits) -> str:
    return f"nested deeper than {limits.max_depth} levels; {limits.what} needs a few"


def _check_size(node: yaml.Node, limits: YamlLimits) -> None:
    """Refuse nesting deeper than ``max_depth`` and more than ``max_values`` values once
    aliases are expanded, counted on the composed node graph (shared nodes counted once per
    use, each node visited once)."""
    expanded: dict[int, int] = {}

    def count(n: yaml.Node, depth: int) -> int:
        if depth > limits.max_depth:
            raise _TooBig(n.start_mark.line + 1, _too_deep(limits))
        if id(n) in expanded:
            return expanded[id(n)]
        children: list[yaml.Node] = []
        if isinstance(n, yaml.MappingNode):
            children = [c for pair in n.value for c in pair]
        elif isinstance(n, yaml.SequenceNode):
            children = list(n.value)
        total = 1 + sum(count(c, depth + 1) for c in children)
        if total > limits.max_values:
            raise _TooBig(
                n.start_mark.line + 1,
                f"holds more than {limits.max_values} values once its YAML aliases are expanded; {limits.what} needs a few hundred",
            )
        expanded[id(n)] = total
        return total

    count(node, 0)


def load_yaml(text: str, source: str, limits: YamlLimits) -> YamlDocument:
    """The data of the YAML ``text`` (``source`` names it in errors), loaded safely within
    ``limits``; any problem is one ``YamlError`` line naming the line of the file."""
    size = len(text.encode("utf-8", "replace"))
    if size > limits.max_bytes:
        raise YamlError(source, None, f"the file is {size} bytes; the limit for {limits.what} is {limits.max_bytes} bytes")
    try:
        loader = _BoundedLoader(text, limits)
        try:
            node = loader.get_single_node()
            if node is not None:
                _check_size(node, limits)
            data = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except _TooBig as exc:
        raise YamlError(source, exc.line, str(exc)) from None
    except RecursionError:
        raise YamlError(source, None, _too_deep(limits)) from None
    except yaml.reader.ReaderError as exc:  # str() of it is three lines
        line = text.count("\n", 0, exc.position) + 1
        raise YamlError(source, line, f"YAML syntax error: character #x{exc.character:04x} is not allowed ({exc.reason})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        problem = getattr(exc, "problem", None) or str(exc)
        raise YamlError(source, None if mark is None else mark.line + 1, f"YAML syntax error: {one_line(problem)}") from None
    pairs = node.value if isinstance(node, yaml.MappingNode) else []
    key_lines = {k.value: k.start_mark.line + 1 for k, _ in pairs if isinstance(k, yaml.ScalarNode)}
    return YamlDocument(data, key_lines)


def read_dataset_yaml(path: Path, what: str, prepare: Callable[[str], str] | None = None) -> YamlDocument:
    """The YAML file ``path`` of a dataset within ``DATASET_YAML``: its size is checked before
    it is read; ``prepare`` edits the text first (EuRoC drops OpenCV's ``%YAML:1.0``).

    Raises:
        DatasetError: naming the file (and line): missing, unreadable, too large or too deep,
            an alias bomb, not YAML, or not a mapping (``what`` describes the keys it needs).
    """
    text = read_text(path, max_bytes=DATASET_YAML.max_bytes)
    try:
        document = load_yaml(prepare(text) if prepare else text, str(path), DATASET_YAML)
    except YamlError as exc:
        raise DatasetError(exc.problem, path, exc.line) from None
    if not isinstance(document.data, dict):
        raise DatasetError(f"expected a YAML mapping of {what}, got {type_name(document.data)}", path)
    return document
