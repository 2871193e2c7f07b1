"""Load pickles safely: every global a pickle names goes through an allow-list.

Unpickling normally imports and calls whatever a file names, so a pickle is code. Here
numpy array/dtype reconstruction, scipy sparse matrices and chumpy ``Ch`` objects (as
inert data holders) are allowed; anything else is refused before any of it runs. Used
for SMPL ``.pkl`` files, ZJU-MoCap's pickled ``annots.npy`` / ``params/*.npy`` and
HumanNeRF's ``cameras.pkl`` / ``mesh_infos.pkl`` (dicts of numpy arrays per frame).
"""

from __future__ import annotations

import codecs
import io
import math
import pickle
import zipfile
from pathlib import Path

import numpy as np
import scipy.sparse

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


_NUMPY = {
    "_reconstruct": _reconstruct,
    "scalar": scalar,
    "ndarray": np.ndarray,
    "dtype": np.dtype,
    "_frombuffer": _frombuffer,
}
_NUMPY_MODULES = {
    "numpy",
    "numpy.core.multiarray",
    "numpy._core.multiarray",
    "numpy.core.numeric",
    "numpy._core.numeric",
}
_SPARSE_MODULES = {
    "scipy.sparse",
    "scipy.sparse.csc",
    "scipy.sparse._csc",
    "scipy.sparse.csr",
    "scipy.sparse._csr",
}
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
        raise AssetError(
            f"refusing to load {self.source}: it names {module}.{name}, which is "
            f"not on the allow-list (numpy arrays, scipy sparse, chumpy Ch); "
            f"see assets_spec/README.md"
        )


def _to_plain(value, key: str, source: str):
    """Turn inert holders into numpy arrays / scipy sparse matrices."""
    if isinstance(value, _ChumpyValue):
        state = getattr(value, "state", None)
        if not isinstance(state, dict) or "x" not in state:
            raise AssetError(
                f"{source}: '{key}' is a chumpy {value.origin} expression, not a "
                "plain Ch array; only Ch arrays can be read without chumpy"
            )
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


def read_pickle(path: Path, what: str = "SMPL pickle") -> dict:
    """Load a pickled dict through :class:`RestrictedUnpickler`; returns plain arrays."""
    try:
        with open(path, "rb") as fh:
            data = RestrictedUnpickler(fh, str(path)).load()
    except AssetError:
        raise
    except Exception as exc:  # truncated / not a pickle / refused reconstructor
        raise AssetError(f"{path}: not a readable {what} ({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict):
        raise AssetError(f"{path}: expected a pickled dict of arrays, got {type(data).__name__}")
    return {k: _to_plain(v, k, str(path)) for k, v in data.items()}


def read_npy_object(path: str | Path) -> object:
    """The object inside a pickled ``.npy`` (np.save of a dict), loaded safely.

    Returns the plain object: a 0-d object array is unwrapped to its item.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            read_header = (
                np.lib.format.read_array_header_1_0
                if version == (1, 0)
                else np.lib.format.read_array_header_2_0
            )
            shape, _, dtype = read_header(fh)
            size = path.stat().st_size
            declared = size if dtype.hasobject else math.prod(shape) * dtype.itemsize
            if declared > MAX_NPZ_BYTES:
                raise AssetError(
                    f"{path}: it holds more than {MAX_NPZ_BYTES / 2**30:g} GiB "
                    f"({declared} bytes); expected a smaller array"
                )
            if dtype.hasobject:
                arr = RestrictedUnpickler(fh, str(path)).load()
            elif size < fh.tell() + declared:
                raise AssetError(f"{path}: truncated: its header declares {declared} bytes of data")
            else:
                arr = np.lib.format.read_array(io.BytesIO(path.read_bytes()), allow_pickle=False)
    except AssetError:
        raise
    except Exception as exc:
        raise AssetError(f"{path}: not a readable .npy file ({type(exc).__name__}: {exc})") from None
    if isinstance(arr, np.ndarray) and arr.dtype == object and arr.shape == ():
        return _plain_tree(arr.item(), str(path))
    return _plain_tree(arr, str(path))


def _plain_tree(value, source: str, key: str = ""):
    if isinstance(value, dict):
        return {k: _plain_tree(v, source, str(k)) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain_tree(v, source, key) for v in value]
    return _to_plain(value, key, source)


#: Most bytes the arrays of one ``.npz`` may decompress to (an SMPL-X model file holds
#: about 250 MB): counted from the archive's directory and each array's header before any
#: array is read, so a small zip of zeros cannot fill memory.
MAX_NPZ_BYTES = 2**30


def _npz_bytes(path: Path, what: str) -> None:
    """AssetError when the arrays of the archive at ``path`` would decompress to more than
    :data:`MAX_NPZ_BYTES`, or an array's header declares more bytes than its member holds."""
    total = 0
    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            total += info.file_size
            if info.filename.endswith(".npy") and total <= MAX_NPZ_BYTES:
                with archive.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    header = np.lib.format.read_array_header_1_0
                    shape, _, dtype = (header if version == (1, 0) else np.lib.format.read_array_header_2_0)(
                        fh
                    )
                declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if declared > info.file_size:
                    raise AssetError(
                        f"{path}: array '{info.filename[:-4]}' declares {shape} {dtype} "
                        f"({declared / 1e6:.3g} MB) but holds {info.file_size / 1e6:.3g} MB; expected {what}"
                    )
            if total > MAX_NPZ_BYTES:
                raise AssetError(
                    f"{path}: its arrays decompress to more than {MAX_NPZ_BYTES / 2**30:g} GiB "
                    f"(the limit for one .npz); expected {what}"
                )


def read_npz(path: str | Path, what: str = "file") -> dict:
    """Every array of an ``.npz`` (``allow_pickle=False``: object arrays are refused);
    one :class:`AssetError` naming the file for a missing or unreadable one."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"{what} not found: {path}")
    if not zipfile.is_zipfile(path):  # np.load would try to unpickle it
        raise AssetError(f"{path}: not an .npz archive (a zip of .npy arrays); expected {what}")
    try:
        _npz_bytes(path, what)
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except AssetError:
        raise
    except ValueError:
        raise AssetError(
            f"{path}: holds object (pickled) arrays, which are refused; expected {what} with numeric arrays"
        ) from None
    except Exception as exc:  # noqa: BLE001 - any damaged archive is the user's file problem
        raise AssetError(f"{path}: not a readable .npz ({type(exc).__name__}); expected {what}") from None
    return data
