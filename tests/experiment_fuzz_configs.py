"""The configs the experiment YAML schema fuzz (test_experiment_fuzz.py) feeds ``sal perturb
--dry-run``'s checks, as hypothesis strategies: mappings built from the schema's real keys,
dataset options, perturbation modules and parameters, with some values replaced by random ones
of random types (``schema_configs``), and YAML text (the example configs and generated ones)
mutated by inserting anchors, aliases, tags, nesting, duplicated lines, tabs and binary junk
(``raw_configs``); ``alias_bomb`` nests YAML aliases."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from hypothesis import strategies as st

from pytest_sal.experiment import schema
from sal_adapters import DATASETS
from sal_modules import PERTURBATIONS, Param, module_class

__all__ = [
    "EXAMPLES",
    "FOLDER",
    "KINDS",
    "MODULES",
    "NASTY_TEXT",
    "SCHEMA_KEYS",
    "SEEDS",
    "SNIPPETS",
    "alias_bomb",
    "boundaries",
    "datasets",
    "keys",
    "module_entries",
    "nodes",
    "numbers",
    "param_values",
    "perturbations",
    "plausible_configs",
    "raw_configs",
    "scalars",
    "schema_configs",
    "searchable",
    "texts",
    "values",
]


EXAMPLES = Path(__file__).resolve().parents[1] / "example_suites" / "configs"


FOLDER = "@FOLDER@"  # stands for a small real image folder in generated configs


# ------------------------------------------------------------------------------ values

NASTY_TEXT = [
    "",
    " ",
    "a\0b",
    "\0",
    "name\n",
    "\n",
    "\r\n",
    "\t",
    "\x1b[31m",
    "\x7f",
    "\x85",
    "\u2028",
    "\ufeff",
    "\ud800",
    "\U0001f600" * 30,
    "é" * 200,
    "x" * 300,
    "x" * 5000,
    "a/" * 3000,
    "../escape",
    "/",
    ".",
    "..",
    "~",
    "~nobody/x",
    "$HOME",
    "${UNDEFINED_SAL_VARIABLE}/x",
    "baseline",
    "none",
    "composite",
    "synthetic",
    "fog",
    "null",
    "true",
    "1e400",
    "0x10",
    "<script>",
    "'",
    '"',
    "\\",
    "%s{}",
    "model.onnx",
    "/dev/zero",
    "/proc/self/mem",
]
numbers = st.one_of(
    st.integers(),
    st.floats(),
    st.sampled_from([0, 1, -1, 2**31, 2**63, -(2**63), 10**30, 10**400, 1e308, -1e-308, 0.5, 1e6, 10**6, 10**9]),
)
texts = st.one_of(st.text(max_size=30), st.sampled_from(NASTY_TEXT))
scalars = st.one_of(st.none(), st.booleans(), numbers, texts)


def param_values(spec: Param) -> st.SearchStrategy[Any]:
    """Valid values of one declared parameter (the module may still refuse a combination)."""
    lo = -1e3 if spec.min is None else spec.min
    hi = 1e3 if spec.max is None else spec.max
    valid: st.SearchStrategy[Any] = {
        "continuous": st.floats(lo, hi),
        "integer": st.integers(int(np.ceil(lo)), int(np.floor(hi))),
        "choice": st.sampled_from(spec.choices or [None]),
        "vector": st.lists(st.floats(lo, hi), min_size=spec.length or 0, max_size=spec.length or 0),
        "flag": st.booleans(),
        "text": texts,
    }[spec.domain]
    return st.one_of(st.none(), valid) if spec.optional else valid


MODULES = [name for name in PERTURBATIONS.names() if name != "composite"]
KINDS = DATASETS.names()
#: Every key the schema knows: sections, dataset options, module parameters.
SCHEMA_KEYS = sorted(
    {*schema.TOP_KEYS, *schema.DATASET_KEYS, *schema.BOUNDARY_KEYS, *schema.PERTURBATION_KEYS, *schema.COMPOSITE_KEYS}
    | {option for kind in KINDS for option in DATASETS.get(kind).option_names()}
    | {param for kind in MODULES for param in module_class(kind).parameters()}
)
keys = st.one_of(st.sampled_from(SCHEMA_KEYS), texts, st.integers(), st.booleans(), st.none())
values = st.recursive(
    scalars, lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(keys, inner, max_size=4)), max_leaves=12
)


@st.composite
def module_entries(draw: st.DrawFn, kind: str) -> dict[str, Any]:
    """``{type, parameters}`` of one module with some of its parameters set."""
    specs = module_class(kind).parameters()
    chosen = draw(st.lists(st.sampled_from(sorted(specs)), unique=True, max_size=3)) if specs else []
    return {"type": kind, "parameters": {name: draw(param_values(specs[name])) for name in chosen}}


@st.composite
def perturbations(draw: st.DrawFn, index: int) -> dict[str, Any]:
    """One entry of ``perturbations``: type none, a module, or a composite of modules."""
    kind = draw(st.sampled_from(["none", "composite", *MODULES]))
    entry: dict[str, Any] = {"name": f"p{index}", "type": kind}
    if kind == "composite":
        steps = draw(st.lists(st.sampled_from(MODULES).flatmap(module_entries), min_size=1, max_size=3))
        entry["parameters"] = {"mode": "sequential", "modules": steps}
    elif kind != "none":
        entry["parameters"] = draw(module_entries(kind))["parameters"]
    if draw(st.booleans()):
        entry["enabled"] = draw(st.booleans())
    return entry


def searchable(entry: dict[str, Any]) -> list[tuple[str, Param]]:
    """(address, spec) of each parameter boundary search may vary in ``entry``."""
    if entry["type"] == "composite":
        steps = entry["parameters"]["modules"]
        return [(f"{s['type']}.{n}", p) for s in steps for n, p in module_class(s["type"]).parameters().items() if p.searchable]
    if entry["type"] == "none":
        return []
    return [(n, p) for n, p in module_class(entry["type"]).parameters().items() if p.searchable]


@st.composite
def boundaries(draw: st.DrawFn, entries: list[dict[str, Any]]) -> dict[str, Any] | None:
    """A ``robustness_boundary`` over a searchable parameter of one entry, if there is one."""
    targets = [(e["name"], a, p) for e in entries for a, p in searchable(e)]
    if not targets:
        return None
    name, address, spec = draw(st.sampled_from(targets))
    space = spec.search_space()
    lower, upper = sorted(draw(st.lists(st.floats(space.min, space.max), min_size=2, max_size=2, unique=True)))
    if space.domain == "integer":
        lower, upper = int(np.floor(lower)), int(np.floor(lower)) + 1
    return {
        "enabled": draw(st.booleans()),
        "target_perturbation": name,
        "parameter": address,
        "lower_bound": lower,
        "upper_bound": upper,
        "tolerance": draw(st.floats(0.01, 10)),
        "max_trials": draw(st.integers(1, 12)),
        "ate_rmse_fail": draw(st.floats(0.01, 10)),
    }


@st.composite
def datasets(draw: st.DrawFn) -> dict[str, Any]:
    """A synthetic dataset, or another kind over the small image folder (``FOLDER``)."""
    kind = draw(st.sampled_from(["synthetic", "synthetic", "folder", *KINDS]))
    dataset: dict[str, Any] = {"type": kind}
    if kind == "synthetic":
        frames = draw(st.one_of(st.integers(1, 30), st.integers(1, 30), st.integers(1, 30), numbers))
        dataset["options"] = {"scene": draw(st.sampled_from(["urban", "indoor"])), "frames": frames}
        if draw(st.booleans()):
            dataset["options"]["seed"] = draw(st.integers(0, 2**32))
    else:
        dataset["path"] = FOLDER
    if draw(st.booleans()):
        dataset["max_frames"] = draw(st.integers(1, 40))
    return dataset


@st.composite
def plausible_configs(draw: st.DrawFn) -> dict[str, Any]:
    """A config that is valid, or nearly (a module may refuse a combination of parameters)."""
    entries = [draw(perturbations(i)) for i in range(draw(st.integers(0, 4)))]
    config: dict[str, Any] = {
        "experiment": {"name": "fuzz", "seed": draw(st.integers(0, 2**31))},
        "dataset": draw(datasets()),
        "perturbations": entries,
        "output": {"base_dir": "results", "create_timestamp_dir": draw(st.booleans())},
    }
    boundary = draw(boundaries(entries))
    if boundary is not None:
        config["robustness_boundary"] = boundary
    return config


def nodes(tree: Any) -> Iterator[dict[Any, Any] | list[Any]]:
    """Every mapping and list in ``tree``, ``tree`` first."""
    if isinstance(tree, (dict, list)):
        yield tree
        for child in tree.values() if isinstance(tree, dict) else tree:
            yield from nodes(child)


@st.composite
def schema_configs(draw: st.DrawFn) -> bytes:
    """A plausible config with up to three values set, added or deleted at random, as YAML."""
    config = draw(plausible_configs())
    for _ in range(draw(st.integers(0, 3))):
        spots = list(nodes(config))
        spot = spots[draw(st.integers(0, len(spots) - 1))]
        action = draw(st.sampled_from(["set", "delete", "add"]))
        if isinstance(spot, dict):
            if action == "add" or not spot:
                spot[draw(keys)] = draw(values)
                continue
            key = draw(st.sampled_from(list(spot)))
        else:
            if action == "add" or not spot:
                spot.append(draw(values))
                continue
            key = draw(st.integers(0, len(spot) - 1))
        if action == "set":
            spot[key] = draw(values)
        else:
            del spot[key]
    style = draw(st.sampled_from([False, True, None]))
    text = yaml.safe_dump(config, sort_keys=False, default_flow_style=style, allow_unicode=draw(st.booleans()))
    return text.encode("utf-8", "surrogatepass")


# ------------------------------------------------------------------------------ YAML text

SEEDS = sorted(p.read_text() for p in EXAMPLES.glob("*.yaml"))
SNIPPETS = [
    "&a ",
    "*a",
    "<<: *a\n",
    "<<: [*a, *a]\n",
    "!!python/object/apply:os.system ['true']",
    "!!binary ",
    "!!timestamp 2001-02-30",
    "2001-02-30",
    "!!float x",
    "!!int x",
    "!!bool maybe",
    "!!set {a}",
    "!!omap [a]",
    "!!pairs [a]",
    "? [a]\n: 1\n",
    "? {a: 1}\n: 1\n",
    "{",
    "[",
    "]",
    "}",
    ": ",
    "- ",
    "\t",
    "---\n",
    "...\n",
    "%YAML 1.1\n",
    "%TAG ! tag:x,2000:\n",
    "'",
    '"',
    "#",
    "\\",
    "|\n",
    ">-\n",
    "\x00",
    "\x1b",
    "\ufeff",
    "\r",
    "\x85",
    "\u2028",
    "1" * 5000,
    ".nan",
    ".inf",
    "-.inf",
    "0x" + "f" * 40,
    "0o777",
    "1_000",
    "0b101",
    "1:20:30",
    "2001-12-14t21:59:43.10-05:00",
    "~",
    "null",
    "yes",
    "on",
    "=",
    "!!str",
    "!<tag:yaml.org,2002:str>",
    "!local ",
    "&anchor\n",
    "*undefined",
    '"a\\0b"',
    '"\\ud800"',
    '"\\x1b[2J"',
    '"' + "x" * 400 + '"',
]


def alias_bomb(levels: int) -> str:
    """``levels`` levels of nine aliases each (9**levels strings once expanded)."""
    text = 'l0: &l0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
    return text + "".join(f"l{i}: &l{i} [{','.join([f'*l{i - 1}'] * 9)}]\n" for i in range(1, levels))


@st.composite
def raw_configs(draw: st.DrawFn) -> bytes:
    """An example or generated config with one to four edits of its text, or of its bytes."""
    text = draw(st.one_of(st.sampled_from(SEEDS), schema_configs().map(lambda b: b.decode("utf-8", "surrogatepass"))))
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        lines = text.splitlines(keepends=True) or [""]
        line = draw(st.integers(0, len(lines) - 1))
        edit = draw(st.sampled_from(["snippet", "text", "delete", "duplicate", "indent", "nest", "bomb"]))
        if edit == "snippet":
            text = text[:at] + draw(st.sampled_from(SNIPPETS)) + text[at:]
        elif edit == "text":
            text = text[:at] + draw(st.text(max_size=20)) + text[at:]
        elif edit == "delete":
            text = text[:at] + text[at + draw(st.integers(1, 200)) :]
        elif edit == "duplicate":  # a key given twice, or a list item
            text = "".join(lines[: line + 1] + lines[line:])
        elif edit == "indent":
            lines[line] = draw(st.sampled_from(["  ", "\t", " " * 37])) + lines[line]
            text = "".join(lines)
        elif edit == "nest":
            depth = draw(st.integers(1, 2000))
            opener, closer = draw(st.sampled_from([("[", "]"), ("{a: ", "}"), ("- ", "")]))
            text = text[:at] + opener * depth + "1" + closer * depth + text[at:]
        else:
            text = alias_bomb(draw(st.integers(1, 9))) + text
    data = text.encode("utf-8", "surrogatepass")
    if draw(st.booleans()):
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.binary(min_size=1, max_size=16)) + data[at:]
    return data
