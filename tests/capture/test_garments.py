"""The garment set: the default capture's images are unchanged, cloth lies off the body
by the stated distances and moves with it, folds are lit geometry on their own part."""

import hashlib

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from texvocab.body import default_body
from texvocab.body.poses import J
from texvocab.capture import open as open_capture
from texvocab.capture.fold_regions import FoldRegions
from texvocab.capture.garment_mesh import FOLD_SKIN, ClothMesh
from texvocab.capture.garment_sets import GARMENT_NAMES, GARMENTS, garment_spec
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthRenderer, SynthSettings, default_cameras, synthesize
from texvocab.errors import AssetError

#: sha256 of the images and masks below, computed with the code before garments existed.
PAINTED_DIGEST = "6dd778c74988428f12753fa1c7f79bc3f8907a2efb1894618c0a369e0de1cb9e"
TINY = SynthSettings(ring_views=2, raised_views=1, size=64, texture_size=128)


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def cloths(body):
    return {name: ClothMesh(body, spec) for name, spec in GARMENTS.items()}


def _bent_elbow() -> np.ndarray:
    pose = np.zeros((24, 3), np.float32)
    pose[J["left_elbow"]] = [0, -np.radians(100), 0]
    return pose


def test_default_garment_renders_what_it_always_did(body):
    poses, trans = make_sequence([("walk", 2), ("squat", 1)], seed=3)
    renderer = SynthRenderer(body, TINY)
    h = hashlib.sha256()
    for t in range(len(poses)):
        for rgb, mask in renderer.render(poses[t], trans[t], default_cameras(TINY)):
            h.update(np.round(rgb * 255).astype(np.uint8).tobytes())
            h.update(mask.tobytes())
    renderer.close()
    assert TINY.garment == "painted" and h.hexdigest() == PAINTED_DIGEST


def test_unknown_garment_is_refused():
    assert GARMENT_NAMES[0] == "painted" and garment_spec("painted") is None
    with pytest.raises(AssetError, match="unknown garment"):
        garment_spec("tutu")


def _distance_to_body(cloth, verts, body_verts) -> np.ndarray:
    """(R,) distance of each cloth vertex to the nearest point of the (subdivided) body."""
    return cKDTree(body_verts).query(verts)[0]


@pytest.mark.parametrize("name", list(GARMENTS))
def test_cloth_lies_off_the_body_by_the_stated_distances(cloths, name):
    cloth = cloths[name]
    d = _distance_to_body(cloth, cloth.rest + cloth.normals * cloth.thickness[:, None], cloth.rest)
    shirt, pants, skin = cloth.region == 2, cloth.region == 3, cloth.region == 0
    assert np.all(cloth.thickness[skin] == 0) and np.all(d[skin] < 1e-9)
    x, y = cloth.rest[:, 0], cloth.rest[:, 1]
    if name in ("hoodie", "loose"):  # 2.5 cm on the chest, up to 6 cm at the hem and sleeves
        chest = shirt & (np.abs(x) < 0.1) & (y > 0.1) & (y < 0.3)
        assert 0.02 < np.median(d[chest]) < 0.03
        assert cloth.thickness[shirt].min() >= 0.015 and cloth.thickness[shirt].max() <= 0.06 + 1e-9
        hem = shirt & (y < y[shirt].min() + 0.03)
        sleeve = shirt & (np.abs(x) > 0.45) & (np.abs(x) < 0.55)
        assert np.median(d[hem]) > 0.045 and np.median(d[sleeve]) > 0.045
    else:
        assert np.allclose(cloth.thickness[shirt], 0.01)
    if name in ("wide-trousers", "loose"):  # up to 10 cm at the ankle hem
        assert cloth.thickness[pants].max() <= 0.1 + 1e-9
        ankle = pants & (y < y[pants].min() + 0.04)
        assert np.percentile(d[ankle], 90) > 0.075
        thigh = pants & (y > -0.45) & (y < -0.35)
        assert np.median(d[thigh]) < 0.04
    else:
        assert np.allclose(cloth.thickness[pants], 0.012)


@pytest.mark.parametrize("name", list(GARMENTS))
def test_cloth_moves_with_the_body(body, cloths, name):
    cloth = cloths[name]
    poses, trans = make_sequence([("walk", 3)], seed=1)
    verts, normals = cloth.posed(poses[1], trans[1])
    posed_body = body.forward(torch.as_tensor(poses[1])[None], torch.as_tensor(trans[1])[None])
    # the body's own surface, posed through the same subdivision (its thickness set to 0)
    from texvocab.body.lbs import skin_points

    w = torch.as_tensor(cloth.weights)
    under = skin_points(torch.as_tensor(cloth.rest)[None], w, posed_body.transforms.double())[0].numpy()
    d = _distance_to_body(cloth, verts, under)
    top = cloth.thickness + cloth.spec.fold_depth
    assert np.percentile(d / np.maximum(top, 1e-3), 95) < 1.1  # within its thickness of the body
    clothed = cloth.thickness > 0
    assert np.median(d[clothed] / cloth.thickness[clothed]) > 0.75  # and still off it
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_folds_follow_the_pose_on_their_own_part(cloths):
    cloth = cloths["hoodie"]
    rest = np.zeros((24, 3), np.float32)
    assert np.all(cloth.fold_depth(rest) == 0)  # no bend, no fold
    depth = cloth.fold_depth(_bent_elbow())
    moved = depth > 1e-4
    assert np.all(depth <= cloth.amplitude + 1e-12) and depth.max() > 0.5 * cloth.amplitude[moved].max()
    elbow = cloth.body.rest_joints.numpy()[J["left_elbow"]]
    assert np.linalg.norm(cloth.rest[moved] - elbow, axis=1).max() < 0.45  # around the left elbow
    assert cloth.rest[moved, 0].min() > 0.1  # on the left arm (+x), not the chest or back
    w = cloth.weights[moved][:, list(FOLD_SKIN["left_elbow"])].sum(1)
    assert w.min() > 0.25  # on the left arm's skin: never on the torso or the other arm
    right = _bent_elbow()
    right[J["right_elbow"]], right[J["left_elbow"]] = [0, np.radians(100), 0], 0
    assert not np.any((cloth.fold_depth(right) > 1e-4) & moved)


def test_folds_are_lit_geometry(body):
    """On a plain grey garment, folds show only through shading: lit, the squat's fold
    ridges change the image inside the silhouette; unlit, almost nothing changes."""
    squat = make_sequence([("squat", 3)], seed=0)[0][2]
    changed = {}
    for lit in (True, False):
        s = SynthSettings(ring_views=1, raised_views=0, size=128, garment="hoodie", lighting=lit)
        renderer = SynthRenderer(body, s)
        renderer.garment.albedo = np.full_like(renderer.garment.albedo, 0.5)
        cam = default_cameras(s)
        ((img, mask),) = renderer.render(squat, np.zeros(3), cam)
        ((flat, flat_mask),) = renderer.render(squat, np.zeros(3), cam, texture_pose=np.zeros((24, 3)))
        inside = mask & flat_mask
        changed[lit] = (np.abs(img - flat).max(-1)[inside] > 2 / 255).sum()
        renderer.close()
    assert 100 < changed[True] < 0.5 * mask.sum()
    assert changed[False] == 0


@pytest.mark.parametrize("name", list(GARMENTS))
def test_synth_writes_each_garment(tmp_path, body, name):
    poses, trans = make_sequence([("walk", 1), ("squat", 2)], seed=2)
    s = SynthSettings(ring_views=2, raised_views=0, size=48, texture_size=128, garment=name)
    out = synthesize(tmp_path / name, poses, trans, num_train=1, body=body, settings=s, progress=False)
    cap = open_capture(out, body=body)
    assert cap.synthetic["settings"]["garment"] == name
    np.testing.assert_allclose(cap.poses, poses, atol=1e-5)  # the fit is the body under the cloth
    painted = SynthRenderer(body, SynthSettings(ring_views=2, raised_views=0, size=48, texture_size=128))
    body_masks = [m for _, m in painted.render(poses[2], trans[2], cap.cameras)]
    for v in range(2):
        mask = cap.mask(v, 2)
        assert mask.sum() > 1.03 * body_masks[v].sum()  # cloth leaves the body's silhouette
        assert (body_masks[v] & ~mask).sum() < 0.01 * body_masks[v].sum()
    regions = FoldRegions.load(out)
    assert regions.region(0, 0) is None and regions.region(2, 1).shape == (48, 48)
    assert regions.region(2, 0).any()  # the squat's folds change the truth
