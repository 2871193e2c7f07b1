"""Read the user's official SMPL files (chumpy pickles, .npz, smpl_uv.obj) without
chumpy, through :mod:`texvocab.io.safe_pickle`."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from texvocab.body.model import BodyModel
from texvocab.errors import AssetError
from texvocab.io.safe_pickle import read_npz, read_pickle
from texvocab.io.spec import load_spec, name_is_accepted, require_valid, spec_ref


def read_model_arrays(path: str | Path) -> dict:
    """Arrays of an SMPL model file (.pkl or .npz), not yet validated."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(
            f"SMPL model file not found: {path}; expected one of the files in {spec_ref('smpl_model')}"
        )
    if path.suffix == ".pkl":
        return read_pickle(path)
    if path.suffix == ".npz":
        return read_npz(path, "SMPL model file")
    raise AssetError(f"{path}: expected an SMPL model .pkl or .npz; see {spec_ref('smpl_model')}")


def read_uv_obj(path: str | Path) -> dict:
    """``vt`` (T, 2), ``ft`` (F, 3) and ``f`` (F, 3), 0-based, from an OBJ with UVs."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"UV file not found: {path}; expected smpl_uv.obj, see {spec_ref('smpl_uv')}")
    vt, f, ft = [], [], []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            if line.startswith("vt "):
                vt.append(line.split()[1:3])
            elif line.startswith("f "):
                corners = line.split()[1:]
                if len(corners) != 3 or any(c.count("/") < 1 for c in corners):
                    raise AssetError(
                        f"{path}:{lineno}: expected a triangle 'f a/ta b/tb c/tc', got {line.strip()!r}"
                    )
                parts = [c.split("/") for c in corners]
                f.append([p[0] for p in parts])
                ft.append([p[1] for p in parts])
    try:
        return {
            "vt": np.asarray(vt, dtype=np.float64).reshape(-1, 2),
            "f": np.asarray(f, dtype=np.int64).reshape(-1, 3) - 1,
            "ft": np.asarray(ft, dtype=np.int64).reshape(-1, 3) - 1,
        }
    except ValueError as exc:
        raise AssetError(f"{path}: malformed vt/f lines ({exc})") from None


def resolve_model_path(path: str | Path, spec_name: str = "smpl_model") -> Path:
    """A file as given, or the first file of the spec's search order inside a folder."""
    path = Path(path).expanduser()
    if path.is_dir():
        order = load_spec(spec_name)["search_order"]
        for rel in order:
            if (path / rel).is_file():
                return path / rel
        tried = ", ".join(str(path / r) for r in order[:3])
        raise AssetError(f"no SMPL model in {path}: looked for {tried}, ...; see {spec_ref(spec_name)}")
    if not path.is_file():
        raise AssetError(
            f"SMPL model file not found: {path}; expected an SMPL model file "
            f"(e.g. SMPL_NEUTRAL.pkl), see {spec_ref(spec_name)}"
        )
    return path


def parents_from_kintree(kintree: np.ndarray) -> np.ndarray:
    """Row 0 of SMPL's kintree_table with the root's sentinel (2^32 - 1) replaced by -1."""
    parents = np.asarray(kintree[0], dtype=np.int64).copy()
    parents[(parents < 0) | (parents >= kintree.shape[1])] = -1
    return parents


def load_smpl(path: str | Path, uv_path: str | Path | None = None):
    """A :class:`~texvocab.body.model.BodyModel` from the user's SMPL model (+ UV file)."""
    path = resolve_model_path(path)
    if not name_is_accepted(path, load_spec("smpl_model")):
        warnings.warn(f"{path.name} is not an official SMPL file name; loading it anyway", stacklevel=2)
    arrays = read_model_arrays(path)
    require_valid(arrays, "smpl_model", str(path))
    vt = ft = None
    if uv_path is None:
        for rel in load_spec("smpl_uv")["search_order"]:
            if (path.parent / rel).is_file():
                uv_path = path.parent / rel
                break
    if uv_path is not None:
        uv = read_uv_obj(uv_path)
        require_valid(uv, "smpl_uv", str(uv_path))
        if not np.array_equal(uv["f"], np.asarray(arrays["f"], dtype=np.int64)):
            raise AssetError(f"{uv_path}: its face vertex indices differ from 'f' in {path}")
        vt, ft = uv["vt"], uv["ft"]
    return BodyModel(
        v_template=arrays["v_template"],
        faces=arrays["f"],
        weights=arrays["weights"],
        parents=parents_from_kintree(arrays["kintree_table"]),
        J_regressor=arrays["J_regressor"],
        shapedirs=arrays["shapedirs"],
        posedirs=arrays.get("posedirs"),
        vt=vt,
        ft=ft,
        name=str(path),
    )
