"""Machine-checkable asset specs (assets_spec/*.json) and the validator behind
``texvocab check-assets``."""
from __future__ import annotations

import json
import re
from functools import lru_cache
from pathlib import Path

import numpy as np

from texvocab.errors import AssetError

SPEC_DIR = Path(__file__).resolve().parent.parent / "assets_spec"


@lru_cache(maxsize=None)
def load_spec(name: str) -> dict:
    """The parsed spec ``assets_spec/<name>.json``."""
    path = SPEC_DIR / f"{name}.json"
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


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
                problems.append(f"{source}: missing key '{key}' ({rule['doc']}), expected "
                                f"shape {tuple(rule['shape'])}")
            continue
        value = arrays[key]
        if hasattr(value, "tocsc") and not rule.get("sparse_ok"):
            problems.append(f"{source}: '{key}' is a sparse matrix; expected a dense array")
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
            problems.append(f"{source}: '{key}' has dtype "
                            f"{np.asarray(getattr(value, 'data', value)).dtype}, expected {rule['dtype']}")
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


def check_path(path: str | Path) -> list[str]:
    """Validate a file or folder of user assets; returns report lines ("OK ..." or problems)."""
    from texvocab.body import smpl_io  # late: avoids an import cycle

    path = Path(path)
    if not path.exists():
        raise AssetError(f"{path}: no such file or folder")
    if path.is_dir() and ((path / "annots.npy").is_file() or (path / "calibration.json").is_file()):
        return check_capture(path)
    files = [path] if path.is_file() else sorted(
        p for p in path.rglob("*") if p.suffix in (".pkl", ".npz", ".obj"))
    if not files:
        return [f"{path}: no SMPL model (.pkl/.npz) or UV (.obj) file found; "
                f"see {spec_ref('smpl_model')}"]
    lines = []
    for f in files:
        kind = "smpl_uv" if f.suffix == ".obj" else "smpl_model"
        try:
            arrays = smpl_io.read_uv_obj(f) if kind == "smpl_uv" else smpl_io.read_model_arrays(f)
        except AssetError as exc:
            lines.append(f"FAIL {exc}")
            continue
        problems = check_arrays(arrays, load_spec(kind), str(f))
        if not name_is_accepted(f, load_spec(kind)):
            lines.append(f"note {f}: name is not one of the official names in {spec_ref(kind)}")
        lines += [f"FAIL {p}" for p in problems] or [f"OK   {f}: valid {kind.replace('_', ' ')}"]
    return lines


def check_capture(path: Path) -> list[str]:
    """Open a capture folder and stat every image and mask it lists."""
    from texvocab.capture import open as open_capture

    try:
        cap = open_capture(path)
    except AssetError as exc:
        return [f"FAIL {exc}"]
    missing = [p for rows in (cap.image_paths, cap.mask_paths) for row in rows for p in row
               if not p.is_file()]
    lines = [f"FAIL {p}: listed by the capture but missing" for p in missing[:10]]
    if len(missing) > 10:
        lines.append(f"FAIL ... and {len(missing) - 10} more missing files")
    from PIL import Image

    for v, cam in enumerate(cap.cameras):
        with Image.open(cap.image_paths[0][v]) as im:
            if im.size != (cam.width, cam.height):
                lines.append(f"FAIL {cap.image_paths[0][v]}: image is {im.size[0]}x{im.size[1]}, "
                             f"calibration says {cam.width}x{cam.height}")
    if not lines:
        lines.append(f"OK   {path}: {cap.layout} capture, {cap.num_views} views x "
                     f"{cap.num_frames} frames ({cap.num_train} training)")
    return lines
