"""Shared fixtures. PyOpenGL binds its platform at first import: choose OSMesa here,
before any test module imports pyrender/OpenGL (one platform per process)."""

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from texvocab.body.parts import SMPL_PARENTS  # noqa: E402

SMPL_ROOT_SENTINEL = 4294967295  # what kintree_table[0, 0] holds in the official files


def toy_smpl_arrays(seed: int = 0, num_betas: int = 10) -> dict:
    """Arrays in the official SMPL key layout for a tiny body: 24 joints, a tetrahedron of
    4 vertices around each joint (V = 96, F = 96). Not SMPL data: random, seeded."""
    rng = np.random.default_rng(seed)
    parents = np.array(SMPL_PARENTS)
    joints = np.zeros((24, 3))
    for j in range(1, 24):
        joints[j] = joints[parents[j]] + rng.normal(0, 0.15, 3)
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) * 0.03
    v = (joints[:, None] + tet[None]).reshape(-1, 3)
    faces = np.concatenate(
        [np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]) + 4 * j for j in range(24)]
    )
    weights = np.zeros((96, 24))
    for j in range(24):
        weights[4 * j : 4 * j + 4, j] = 0.8 if j else 1.0
        if j:
            weights[4 * j : 4 * j + 4, parents[j]] = 0.2
    J_regressor = np.zeros((24, 96))
    for j in range(24):
        J_regressor[j, 4 * j : 4 * j + 4] = 0.25
    kintree = np.stack([parents, np.arange(24)]).astype(np.int64)
    kintree[0, 0] = SMPL_ROOT_SENTINEL
    return {
        "v_template": v,
        "f": faces.astype(np.uint32),
        "weights": weights,
        "J_regressor": J_regressor,
        "kintree_table": kintree,
        "shapedirs": rng.normal(0, 0.01, (96, 3, num_betas)),
        "posedirs": rng.normal(0, 0.001, (96, 3, 207)),
        "J": joints,
        "bs_style": "lbs",
        "bs_type": "lrotmin",
    }


@pytest.fixture
def toy_arrays():
    return toy_smpl_arrays()


# --- torch caches: pretrained weights present or absent, without touching the user's ---


@pytest.fixture
def empty_torch_home(tmp_path, monkeypatch):
    """TORCH_HOME set to an empty folder, with the once-per-process log memories cleared
    (so each test sees its own "weights absent" line)."""
    from texvocab.io import weights
    from texvocab.method import encoder

    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    monkeypatch.setattr(weights, "_logged", set())
    monkeypatch.setattr(encoder, "_fallback_logged", set())
    return tmp_path


# --- shared scenes: the posed default body with its analytic field, a tiny synthetic capture ---


@pytest.fixture(scope="module")
def body():
    """Posed default body ('walk'), its analytic field, shell and a 64² synthetic view."""
    import torch  # imported here: conftest stays light for the tests that need neither
    from render_cases import DELTA

    from texvocab.body import default_body
    from texvocab.body.poses import preset
    from texvocab.capture.synth import SynthSettings, default_cameras
    from texvocab.render import ShellGeometry
    from texvocab.render.analytic import MeshSDFField

    model = default_body()
    pose, trans = preset("walk")
    out = model.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
    v, f = out.vertices[0], model.faces
    return {
        "v": v,
        "f": f,
        "joints": out.joints[0],
        "field": MeshSDFField(v, f, beta=0.003, voxel=0.015),
        "shell": ShellGeometry.build(v, f, DELTA),
        "camera": default_cameras(SynthSettings())[1].scaled(0.25),
    }


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A tiny synthetic capture: 5 frames (4 train) of walk and arm raise, 6 ring views, 64²."""
    from texvocab.body import default_body
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize

    poses, trans = make_sequence([("walk", 3), ("arm_raise", 2)], seed=5)
    root = synthesize(
        tmp_path_factory.mktemp("e2e") / "cap",
        poses,
        trans,
        4,
        default_body(),
        SynthSettings(ring_views=6, raised_views=0, size=64, texture_size=256),
        progress=False,
    )
    return root


@pytest.fixture
def one_thread():
    """Bit-exact comparisons need one thread: with several, oneDNN's convolution backward
    reduces partial sums in an order that depends on thread timing (seen under load)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
