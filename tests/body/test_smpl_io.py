"""The user's SMPL files: official-layout pickles without chumpy, npz, UV obj, and refusal
of anything else a pickle might name."""

import os
import pickle

import numpy as np
import pytest
import torch
from smpl_files import write_official_pickle

from texvocab.body.smpl_io import load_smpl, read_model_arrays, read_uv_obj
from texvocab.errors import AssetError


def _write_uv(path, faces, seed=0):
    rng = np.random.default_rng(seed)
    ft = np.arange(faces.size).reshape(-1, 3)
    vt = rng.random((faces.size, 2))
    lines = ["v 0 0 0" for _ in range(int(faces.max()) + 1)]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in vt]
    lines += ["f " + " ".join(f"{a + 1}/{b + 1}" for a, b in zip(fr, tr)) for fr, tr in zip(faces, ft)]
    path.write_text("\n".join(lines) + "\n")
    return vt, ft


@pytest.mark.parametrize("protocol", [0, 2])
def test_official_pickle_loads_without_chumpy(tmp_path, toy_arrays, monkeypatch, protocol):
    path = tmp_path / "basicModel_neutral_lbs_10_207_0_v1.0.0.pkl"
    write_official_pickle(path, toy_arrays, monkeypatch, protocol=protocol)
    assert "chumpy" not in __import__("sys").modules
    arrays = read_model_arrays(path)
    np.testing.assert_array_equal(arrays["shapedirs"], toy_arrays["shapedirs"])
    np.testing.assert_array_equal(arrays["J_regressor"].toarray(), toy_arrays["J_regressor"])
    body = load_smpl(path)
    assert body.num_vertices == 96 and body.num_betas == 10
    assert body.parents[0] == -1 and body.parents.tolist()[1:4] == [0, 0, 0]
    # Joints come from the regressor; zero pose reproduces the template.
    out = body.forward(torch.zeros(1, 24, 3))
    np.testing.assert_allclose(out.vertices[0].numpy(), toy_arrays["v_template"], atol=1e-6)


def test_folder_search_and_uv_next_to_model(tmp_path, toy_arrays, monkeypatch):
    write_official_pickle(tmp_path / "SMPL_NEUTRAL.pkl", toy_arrays, monkeypatch)
    vt, ft = _write_uv(tmp_path / "smpl_uv.obj", toy_arrays["f"].astype(np.int64))
    body = load_smpl(tmp_path)
    np.testing.assert_allclose(body.vt.numpy(), vt, atol=1e-6)
    np.testing.assert_array_equal(body.ft.numpy(), ft)


def test_uv_faces_must_match_model(tmp_path, toy_arrays, monkeypatch):
    write_official_pickle(tmp_path / "SMPL_NEUTRAL.pkl", toy_arrays, monkeypatch)
    _write_uv(tmp_path / "smpl_uv.obj", toy_arrays["f"][::-1].astype(np.int64))
    with pytest.raises(AssetError, match="face vertex indices differ"):
        load_smpl(tmp_path)


def test_npz_model(tmp_path, toy_arrays):
    path = tmp_path / "SMPL_NEUTRAL.npz"
    np.savez(path, **{k: v for k, v in toy_arrays.items() if isinstance(v, np.ndarray)})
    body = load_smpl(path)
    assert body.posedirs.shape == (207, 96 * 3)


def test_npz_with_object_array_is_refused(tmp_path, toy_arrays):
    path = tmp_path / "SMPL_NEUTRAL.npz"
    np.savez(path, v_template=np.array([{"a": 1}], dtype=object))
    with pytest.raises(AssetError, match=r"object \(pickled\) arrays"):
        read_model_arrays(path)


class _Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.mark.parametrize("protocol", [0, 2, 5])
def test_malicious_pickle_is_refused_and_runs_nothing(tmp_path, toy_arrays, protocol):
    marker = tmp_path / "pwned"
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    payload = {"v_template": toy_arrays["v_template"], "weights": _Evil(marker)}
    path.write_bytes(pickle.dumps(payload, protocol=protocol))
    with pytest.raises(
        AssetError,
        match=r"refusing to load .*SMPL_NEUTRAL\.pkl: it names "
        r"(posix|os|nt)\.system",
    ):
        load_smpl(path)
    assert not marker.exists()


def test_reconstructor_cannot_build_foreign_classes(tmp_path):
    # copyreg._reconstructor(cls=builtins.object, base=builtins.set) is allowed by name but
    # must not construct anything that is not an inert holder.
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    blob = b"ccopy_reg\n_reconstructor\n(c__builtin__\nset\nc__builtin__\nobject\nNtR."
    path.write_bytes(blob)
    with pytest.raises(AssetError, match="not a readable SMPL pickle"):
        read_model_arrays(path)


def test_missing_model_file_names_path_and_spec(tmp_path):
    missing = tmp_path / "SMPL_NEUTRAL.pkl"
    with pytest.raises(AssetError) as err:
        load_smpl(missing)
    msg = str(err.value)
    assert str(missing) in msg and "assets_spec/smpl_model.json" in msg


def test_empty_folder_lists_where_it_looked(tmp_path):
    with pytest.raises(AssetError, match=r"no SMPL model in .*SMPL_NEUTRAL\.pkl"):
        load_smpl(tmp_path)


def test_wrong_shape_names_key_and_expected_shape(tmp_path, toy_arrays, monkeypatch):
    toy_arrays["weights"] = toy_arrays["weights"][:, :23]
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    write_official_pickle(path, toy_arrays, monkeypatch)
    with pytest.raises(AssetError, match=r"'weights' has shape \(96, 23\), expected \(96, 24\)"):
        load_smpl(path)


def test_missing_key_is_named(tmp_path, toy_arrays, monkeypatch):
    del toy_arrays["kintree_table"]
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    write_official_pickle(path, toy_arrays, monkeypatch)
    with pytest.raises(AssetError, match="missing key 'kintree_table'"):
        load_smpl(path)


def test_truncated_pickle(tmp_path, toy_arrays, monkeypatch):
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    write_official_pickle(path, toy_arrays, monkeypatch)
    path.write_bytes(path.read_bytes()[:500])
    with pytest.raises(AssetError, match="not a readable SMPL pickle"):
        read_model_arrays(path)


def test_uv_obj_rejects_quads(tmp_path):
    path = tmp_path / "smpl_uv.obj"
    path.write_text("vt 0 0\nf 1/1 2/1 3/1 4/1\n")
    with pytest.raises(AssetError, match=r"smpl_uv\.obj:2: expected a triangle"):
        read_uv_obj(path)
