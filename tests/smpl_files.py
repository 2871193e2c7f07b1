"""Write SMPL-layout files the way the official ones are: a protocol-2 Python pickle with
chumpy ``Ch`` objects and a scipy ``csc_matrix`` J_regressor — without chumpy installed."""

from __future__ import annotations

import pickle
import sys
import types

import numpy as np
import scipy.sparse


class _FakeCh:
    """Pickles like chumpy.ch.Ch: state dict with the array under 'x'."""

    def __init__(self, x):
        self.x = np.asarray(x)

    def __getstate__(self):
        return {"x": self.x, "_dirty_vars": set(), "_itr": None, "_parents": {}}


class _FakeCsc:
    """Pickles like scipy.sparse.csc.csc_matrix from the 2015 files."""

    def __init__(self, dense):
        m = scipy.sparse.csc_matrix(dense)
        self.state = {
            "_shape": m.shape,
            "data": m.data,
            "indices": m.indices,
            "indptr": m.indptr,
            "maxprint": 50,
            "format": "csc",
        }

    def __getstate__(self):
        return self.state


def write_official_pickle(
    path, arrays: dict, monkeypatch, chumpy_keys=("shapedirs", "v_template", "J"), protocol: int = 2
) -> None:
    """Write ``arrays`` as an official-style SMPL .pkl (chumpy Ch + sparse J_regressor)."""
    ch_mod, ch_ch = types.ModuleType("chumpy"), types.ModuleType("chumpy.ch")
    sp_mod = types.ModuleType("scipy.sparse.csc")
    _FakeCh.__module__, _FakeCh.__qualname__, _FakeCh.__name__ = "chumpy.ch", "Ch", "Ch"
    _FakeCsc.__module__, _FakeCsc.__qualname__, _FakeCsc.__name__ = (
        "scipy.sparse.csc",
        "csc_matrix",
        "csc_matrix",
    )
    ch_ch.Ch, sp_mod.csc_matrix = _FakeCh, _FakeCsc
    data = {}
    for k, v in arrays.items():
        if k in chumpy_keys:
            data[k] = _FakeCh(v)
        elif k == "J_regressor":
            data[k] = _FakeCsc(v)
        else:
            data[k] = v
    # The fake modules exist only while dumping; loading runs without them.
    with monkeypatch.context() as m, open(path, "wb") as fh:
        m.setitem(sys.modules, "chumpy", ch_mod)
        m.setitem(sys.modules, "chumpy.ch", ch_ch)
        m.setitem(sys.modules, "scipy.sparse.csc", sp_mod)
        pickle.dump(data, fh, protocol=protocol)
