"""Machine-checkable asset specs (assets_spec/*.json, shipped inside the package as
``texvocab.assets_spec``): load a spec, check arrays against it, one error naming the spec.

A leaf: it imports nothing of the project but its errors, so every reader may use it."""

from __future__ import annotations

import json
import re
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from texvocab.errors import AssetError

#: The specs as installed: the repository's assets_spec/ folder is the package
#: ``texvocab.assets_spec`` (a package-dir mapping in pyproject.toml).
SPEC_DIR = resources.files("texvocab.assets_spec")


@lru_cache(maxsize=None)
def load_spec(name: str) -> dict:
    """The parsed spec ``assets_spec/<name>.json``."""
    return json.loads((SPEC_DIR / f"{name}.json").read_text(encoding="utf-8"))


def spec_ref(name: str) -> str:
    """How messages point a person at a spec."""
    return f"assets_spec/{name}.json (explained in assets_spec/README.md)"


def name_is_accepted(path: Path, spec: dict) -> bool:
    return any(re.match(p, path.name) for p in spec.get("accepted_names", []))


def _dtype_ok(arr, kind: str) -> bool:
    got = np.asarray(arr.data if hasattr(arr, "tocsc") else arr).dtype.kind
    return got in {"float": "f", "int": "iu"}[kind] or (kind == "float" and got in "iu")


def check_arrays(arrays: dict, spec: dict, source: str) -> list[str]:
    """Every way ``arrays`` differs from ``spec``; empty when all is well.

    Symbolic dimensions (strings such as ``"S"``) match any size but must agree across keys.
    """
    problems: list[str] = []
    bound: dict[str, int] = {}
    for key, rule in spec["keys"].items():
        if key not in arrays:
            if rule.get("required", True):
                problems.append(
                    f"{source}: missing key '{key}' ({rule['doc']}), expected shape {tuple(rule['shape'])}"
                )
            continue
        value = arrays[key]
        if hasattr(value, "tocsc") and not rule.get("sparse_ok"):
            problems.append(f"{source}: '{key}' is a sparse matrix; expected a dense array")
            continue
        if not hasattr(value, "shape"):  # a string, a number, a list: what it is as an array
            kind = type(value).__name__
            try:
                value = np.asarray(value)
            except (TypeError, ValueError):  # a ragged list
                value = np.asarray(None)
            if value.dtype.kind in "OUS":
                problems.append(
                    f"{source}: '{key}' is a {kind}; expected numbers of shape {tuple(rule['shape'])}"
                )
                continue
        shape = tuple(value.shape)
        want = rule["shape"]
        ok = len(shape) == len(want)
        for got, dim in zip(shape, want):
            if isinstance(dim, str):
                ok &= bound.setdefault(dim, got) == got
            else:
                ok &= got == dim
        if not ok:
            shown = tuple(bound.get(d, d) if isinstance(d, str) else d for d in want)
            problems.append(f"{source}: '{key}' has shape {shape}, expected {shown}")
        elif not _dtype_ok(value, rule["dtype"]):
            problems.append(
                f"{source}: '{key}' has dtype "
                f"{np.asarray(getattr(value, 'data', value)).dtype}, expected {rule['dtype']}"
            )
        elif rule["dtype"] == "float":
            data = value.data if hasattr(value, "tocsc") else np.asarray(value)
            if not np.isfinite(data).all():
                problems.append(f"{source}: '{key}' contains non-finite values")
    return problems


def require_valid(arrays: dict, spec_name: str, source: str) -> None:
    """Raise one :class:`AssetError` listing what is wrong, pointing at the spec."""
    problems = check_arrays(arrays, load_spec(spec_name), source)
    if problems:
        more = f" (+{len(problems) - 1} more)" if len(problems) > 1 else ""
        raise AssetError(f"{problems[0]}{more}; see {spec_ref(spec_name)}")
