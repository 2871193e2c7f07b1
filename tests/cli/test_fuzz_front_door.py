"""Fuzzed front door (hypothesis): the settings parser, the pose-file reader, the capture
reader and the checkpoint loader, fed random inputs, either succeed or raise a
TexvocabError (the CLI's one-line error) — never another exception — and write nothing
outside their output folder."""

import shutil
import string

import numpy as np
import torch
from disk_snapshot import snapshot
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from texvocab.capture import open as open_capture
from texvocab.capture.synth import load_pose_file
from texvocab.errors import TexvocabError
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.settings import FLAT_NAMES, Settings

FUZZ = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
KEYS = list(FLAT_NAMES) + list(Settings().dotted()) + ["nosuch", "field", "render", "render.nosuch"]
VALUES = st.one_of(
    st.sampled_from(
        [
            "nan",
            "inf",
            "-inf",
            "-1",
            "0",
            "1e30",
            "none",
            "true",
            "1,2",
            "abc",
            "",
            "0.5",
            "3",
            "part",
            "paper",
            "auto",
        ]
    ),
    st.text(string.printable, max_size=8),
    st.integers(-(10**6), 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
)


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(KEYS), VALUES), max_size=4))
def test_settings_overrides(items):
    try:
        s = Settings().with_overrides([f"{k}={v}" for k, v in items])
    except TexvocabError:
        return
    assert Settings.from_dict(s.to_dict()) == s  # what is accepted round-trips


ARRAYS = st.one_of(
    st.integers(0, 4)
    .flatmap(lambda t: st.sampled_from([(t, 72), (t, 24, 3), (t, 3), (t,), (t, 156), (t, 5, 3)]))
    .flatmap(
        lambda shape: st.sampled_from([np.float32, np.float64, np.int64, np.bool_]).flatmap(
            lambda dt: st.one_of(st.floats(-1e30, 1e30), st.sampled_from([np.nan, np.inf])).map(
                lambda v: np.full(shape, v).astype(dt)
            )
        )
    ),
    st.sampled_from([np.array(["a", "b"]), np.zeros((2, 24, 3), np.complex64), np.array(3.0)]),
)


@FUZZ
@given(st.dictionaries(st.sampled_from(["poses", "trans", "betas", "other"]), ARRAYS, max_size=3))
def test_pose_file_reader(tmp_path_factory, arrays):
    path = tmp_path_factory.mktemp("poses") / "p.npz"
    np.savez(path, **arrays)
    try:
        poses, trans = load_pose_file(path)
    except TexvocabError:
        return
    assert poses.shape[1:] == (24, 3) and trans.shape == (len(poses), 3)
    assert np.isfinite(poses).all() and np.isfinite(trans).all()


JUNK = st.recursive(
    st.one_of(
        st.none(),
        st.integers(-3, 10**9),
        st.floats(),
        st.text(max_size=5),
        st.sampled_from([np.zeros((3, 3)), np.zeros((4, 2, 2)), torch.zeros(2)]),
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=3), inner, max_size=3)
    ),
    max_leaves=6,
)


@FUZZ
@given(st.sampled_from(["cams", "ims", "K", "R", "T", "D", "ims.0", "ims.0.ims"]), JUNK)
def test_capture_reader(world, tmp_path_factory, where, junk):
    root = tmp_path_factory.mktemp("cap") / "cap"
    shutil.copytree(world / "cap", root, ignore=shutil.ignore_patterns("texvocab_cache"))
    annots = np.load(root / "annots.npy", allow_pickle=True).item()
    if where in ("cams", "ims"):
        annots[where] = junk
    elif where.startswith("ims."):
        if where == "ims.0":
            annots["ims"][0] = junk
        else:
            annots["ims"][0]["ims"] = junk
    else:
        annots["cams"][where] = junk
    np.save(root / "annots.npy", annots, allow_pickle=True)
    before = snapshot(world)
    try:
        cap = open_capture(root)
        cap.image(0, 0)
    except TexvocabError:
        pass
    assert snapshot(world) == before


def _outside_cache(root):
    return {k: v for k, v in snapshot(root).items() if "texvocab_cache" not in k}


CKPT_PARTS = ["settings", "vocab", "model", "num_train", "capture", "capture_identity", "step"]


@FUZZ
@given(st.sampled_from(CKPT_PARTS), JUNK, st.booleans())
def test_checkpoint_loader(world, tmp_path_factory, part, junk, nested):
    ck = torch.load(world / "run" / "checkpoint.pt", weights_only=True)
    if nested and isinstance(ck[part], dict) and ck[part]:
        ck[part][next(iter(ck[part]))] = junk
    else:
        ck[part] = junk
    path = tmp_path_factory.mktemp("ck") / "checkpoint.pt"
    torch.save(ck, path)
    before = _outside_cache(world)
    try:
        load_avatar(path, progress=False)
    except TexvocabError:
        pass
    assert _outside_cache(world) == before  # only the capture's texture-map cache may fill
