"""Read the user's official SMPL files without chumpy, safely.

SMPL ``.pkl`` files are Python 2 pickles holding chumpy objects. Unpickling normally
imports and calls whatever a file names, so a pickle is code. Here every global a
pickle names goes through an allow-list: numpy array/dtype reconstruction, scipy sparse
matrices and chumpy ``Ch`` objects become inert data holders, and anything else is
refused before any of it runs.
"""
from __future__ import annotations

import codecs
import pickle
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse

from texvocab.assets import load_spec, name_is_accepted, require_valid, spec_ref
from texvocab.errors import AssetError

try:  # numpy >= 2
    from numpy._core.multiarray import _reconstruct, scalar
    from numpy._core.numeric import _frombuffer
except ImportError:  # pragma: no cover - numpy 1.x
    from numpy.core.multiarray import _reconstruct, scalar
    from numpy.core.numeric import _frombuffer


class _Inert:
    """Holds the pickled state of an allowed foreign object; runs none of its code."""

    origin = "?"

    def __setstate__(self, state):
        self.state = state


class _ChumpyValue(_Inert):
    origin = "chumpy"


class _SparseValue(_Inert):
    origin = "scipy.sparse"


def _safe_reconstructor(cls, base, state):
    """Stand-in for copyreg._reconstructor that only builds inert holders."""
    if not (isinstance(cls, type) and issubclass(cls, _Inert)) or base is not object:
        raise pickle.UnpicklingError(f"copyreg._reconstructor with {cls!r}, {base!r} refused")
    return cls.__new__(cls)


_NUMPY = {"_reconstruct": _reconstruct, "scalar": scalar, "ndarray": np.ndarray,
          "dtype": np.dtype, "_frombuffer": _frombuffer}
_NUMPY_MODULES = {"numpy", "numpy.core.multiarray", "numpy._core.multiarray",
                  "numpy.core.numeric", "numpy._core.numeric"}
_SPARSE_MODULES = {"scipy.sparse", "scipy.sparse.csc", "scipy.sparse._csc",
                   "scipy.sparse.csr", "scipy.sparse._csr"}
_BUILTINS = {"object": object, "set": set, "frozenset": frozenset, "complex": complex}


class RestrictedUnpickler(pickle.Unpickler):
    """Unpickler that resolves only allow-listed globals (see module docstring)."""

    def __init__(self, file, source: str):
        super().__init__(file, encoding="latin1")
        self.source = source

    def find_class(self, module: str, name: str):
        if module in _NUMPY_MODULES and _NUMPY.get(name) is not None:
            return _NUMPY[name]
        if module in ("copy_reg", "copyreg") and name == "_reconstructor":
            return _safe_reconstructor
        if module == "_codecs" and name == "encode":  # bytes in protocol-2 pickles
            return codecs.encode
        if module in ("__builtin__", "builtins") and name in _BUILTINS:
            return _BUILTINS[name]
        if module == "chumpy" or module.startswith("chumpy."):
            return type(name, (_ChumpyValue,), {"origin": f"{module}.{name}"})
        if module in _SPARSE_MODULES and name in ("csc_matrix", "csr_matrix"):
            return type(name, (_SparseValue,), {"origin": f"{module}.{name}"})
        raise AssetError(f"refusing to load {self.source}: it names {module}.{name}, which is "
                         f"not on the allow-list (numpy arrays, scipy sparse, chumpy Ch); "
                         f"see {spec_ref('smpl_model')}")


def _to_plain(value, key: str, source: str):
    """Turn inert holders into numpy arrays / scipy sparse matrices."""
    if isinstance(value, _ChumpyValue):
        state = getattr(value, "state", None)
        if not isinstance(state, dict) or "x" not in state:
            raise AssetError(f"{source}: '{key}' is a chumpy {value.origin} expression, not a "
                             "plain Ch array; only Ch arrays can be read without chumpy")
        return np.asarray(state["x"])
    if isinstance(value, _SparseValue):
        s = getattr(value, "state", {})
        try:
            cls = scipy.sparse.csr_matrix if "csr" in value.origin else scipy.sparse.csc_matrix
            shape = s.get("_shape", s.get("shape"))
            return cls((s["data"], s["indices"], s["indptr"]), shape=shape)
        except (KeyError, TypeError, ValueError) as exc:
            raise AssetError(f"{source}: '{key}' is a malformed sparse matrix ({exc})") from None
    return value


def read_pickle(path: Path) -> dict:
    """Load an SMPL ``.pkl`` through :class:`RestrictedUnpickler`; returns plain arrays."""
    try:
        with open(path, "rb") as fh:
            data = RestrictedUnpickler(fh, str(path)).load()
    except AssetError:
        raise
    except Exception as exc:  # truncated / not a pickle / refused reconstructor
        raise AssetError(f"{path}: not a readable SMPL pickle ({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict):
        raise AssetError(f"{path}: expected a pickled dict of arrays, got {type(data).__name__}")
    return {k: _to_plain(v, k, str(path)) for k, v in data.items()}


def read_model_arrays(path: str | Path) -> dict:
    """Arrays of an SMPL model file (.pkl or .npz), not yet validated."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"SMPL model file not found: {path}; expected one of the files in "
                         f"{spec_ref('smpl_model')}")
    if path.suffix == ".pkl":
        return read_pickle(path)
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as npz:
                return {k: npz[k] for k in npz.files}
        except ValueError as exc:
            raise AssetError(f"{path}: object arrays are refused in .npz model files ({exc})") from None
        except Exception as exc:
            raise AssetError(f"{path}: not a readable .npz ({exc})") from None
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
                    raise AssetError(f"{path}:{lineno}: expected a triangle 'f a/ta b/tb c/tc', "
                                     f"got {line.strip()!r}")
                parts = [c.split("/") for c in corners]
                f.append([p[0] for p in parts])
                ft.append([p[1] for p in parts])
    try:
        return {"vt": np.asarray(vt, dtype=np.float64).reshape(-1, 2),
                "f": np.asarray(f, dtype=np.int64).reshape(-1, 3) - 1,
                "ft": np.asarray(ft, dtype=np.int64).reshape(-1, 3) - 1}
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
        raise AssetError(f"no SMPL model in {path}: looked for {tried}, ...; "
                         f"see {spec_ref(spec_name)}")
    if not path.is_file():
        raise AssetError(f"SMPL model file not found: {path}; expected an SMPL model file "
                         f"(e.g. SMPL_NEUTRAL.pkl), see {spec_ref(spec_name)}")
    return path


def parents_from_kintree(kintree: np.ndarray) -> np.ndarray:
    """Row 0 of SMPL's kintree_table with the root's sentinel (2^32 - 1) replaced by -1."""
    parents = np.asarray(kintree[0], dtype=np.int64).copy()
    parents[(parents < 0) | (parents >= kintree.shape[1])] = -1
    return parents


def load_smpl(path: str | Path, uv_path: str | Path | None = None):
    """A :class:`~texvocab.body.model.BodyModel` from the user's SMPL model (+ UV file)."""
    from texvocab.body.model import BodyModel

    path = resolve_model_path(path)
    if not name_is_accepted(path, load_spec("smpl_model")):
        warnings.warn(f"{path.name} is not an official SMPL file name; loading it anyway",
                      stacklevel=2)
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
        v_template=arrays["v_template"], faces=arrays["f"], weights=arrays["weights"],
        parents=parents_from_kintree(arrays["kintree_table"]), J_regressor=arrays["J_regressor"],
        shapedirs=arrays["shapedirs"], posedirs=arrays.get("posedirs"), vt=vt, ft=ft,
        name=str(path))
