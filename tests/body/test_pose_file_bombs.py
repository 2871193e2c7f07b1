"""Pose files (and every .npz a capture holds) that would fill memory: a small zip of zeros
that decompresses past the limit, and an array header declaring more than its member
holds, are refused from the archive's directory and headers, before any array is read."""

import zipfile

import numpy as np
import pytest

from texvocab.body.pose_files import read_pose_sequence
from texvocab.errors import AssetError
from texvocab.io import safe_pickle


def _zeros_npz(path, rows: int, declared_rows: int | None = None) -> None:
    """An .npz whose 'poses' member holds ``rows`` x 72 float64 zeros, its header
    declaring ``declared_rows`` rows (default: the truth)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        with archive.open("poses.npy", "w") as fh:
            shape = (declared_rows or rows, 72)
            np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": shape})
            fh.write(bytes(rows * 72 * 8))


def test_a_zip_of_zeros_past_the_limit_is_refused_before_reading(tmp_path, monkeypatch):
    path = tmp_path / "bomb.npz"
    _zeros_npz(path, rows=8000)  # 4.6 MB of zeros in a few kB
    assert path.stat().st_size < 40_000
    monkeypatch.setattr(safe_pickle, "MAX_NPZ_BYTES", 2**20)
    monkeypatch.setattr(safe_pickle.np, "load", lambda *a, **k: pytest.fail("np.load ran"))
    with pytest.raises(AssetError, match=r"bomb\.npz: its arrays decompress to more than .* GiB"):
        read_pose_sequence(path)


def test_a_header_declaring_more_than_its_member_holds_is_refused(tmp_path):
    path = tmp_path / "liar.npz"
    _zeros_npz(path, rows=2, declared_rows=10**9)
    with pytest.raises(AssetError, match=r"array 'poses' declares \(1000000000, 72\) float64 .* but holds"):
        read_pose_sequence(path)


def test_a_pose_file_within_the_limit_reads(tmp_path):
    path = tmp_path / "ok.npz"
    _zeros_npz(path, rows=3)
    assert read_pose_sequence(path).poses.shape == (3, 24, 3)


def test_the_limit_holds_an_smplx_model_file():
    assert safe_pickle.MAX_NPZ_BYTES >= 500e6  # SMPL-X's model arrays are about 250 MB


def _npy(path, shape, rows_written: int, dtype="<f8") -> None:
    """A .npy whose header declares ``shape`` with ``rows_written`` rows of zeros after it."""
    with open(path, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": dtype, "fortran_order": False, "shape": shape})
        fh.write(bytes(rows_written * int(np.prod(shape[1:])) * np.dtype(dtype).itemsize))


def test_an_npy_declaring_more_than_the_limit_or_than_it_holds_is_refused(tmp_path, monkeypatch):
    good = tmp_path / "good.npy"
    _npy(good, (4, 3), 4)
    np.testing.assert_array_equal(safe_pickle.read_npy_object(good), np.zeros((4, 3)))
    huge = tmp_path / "huge.npy"
    _npy(huge, (10**7, 10**7), 1)  # 800 TB declared in a few hundred bytes
    with pytest.raises(AssetError, match=r"huge.npy: it holds more than 1 GiB"):
        safe_pickle.read_npy_object(huge)
    monkeypatch.setattr(safe_pickle.np.lib.format, "read_array", lambda *a, **k: pytest.fail("read"))
    short = tmp_path / "short.npy"
    _npy(short, (1000, 3), 10)
    with pytest.raises(AssetError, match=r"short.npy: truncated: its header declares 24000 bytes"):
        safe_pickle.read_npy_object(short)
    monkeypatch.setattr(safe_pickle, "MAX_NPZ_BYTES", 2**10)
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array({"K": list(range(2000))}, dtype=object), allow_pickle=True)
    with pytest.raises(AssetError, match=r"obj.npy: it holds more than"):
        safe_pickle.read_npy_object(obj)
