"""The body's girth (texvocab.body.girth): per-joint offsets blended over the surface by the
skinning weights, normals that point out of the body, and posing linear in the offsets."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.girth import posed_normals, symmetric_groups, vertex_normals, vertex_offsets
from texvocab.body.parts import JOINT_NAMES


@pytest.fixture(scope="module")
def body():
    return default_body()


def test_the_offsets_blend_over_the_surface_by_the_skinning_weights(body):
    offsets = np.linspace(-0.01, 0.05, body.num_joints)
    along = vertex_offsets(body, offsets)
    assert float(along.min()) >= -0.01 - 1e-9 and float(along.max()) <= 0.05 + 1e-9
    forearm = body.weights[:, JOINT_NAMES.index("left_elbow")] > 0.99
    elbow = float(offsets[JOINT_NAMES.index("left_elbow")])
    assert forearm.sum() > 20 and float((along[forearm] - elbow).abs().max()) < 1e-3
    normals = vertex_normals(body.v_template, body.faces)
    assert torch.allclose(normals.norm(dim=1), torch.ones(len(normals), dtype=torch.float64))
    with pytest.raises(ValueError, match="girth offsets"):
        vertex_offsets(body, np.zeros(3))


def test_normals_point_out_of_the_body(body):
    """A forearm's vertices moved 2 cm along their normals lie 2 cm farther from its bone."""
    j = body.rest_joints.double()
    a, b = j[JOINT_NAMES.index("left_elbow")], j[JOINT_NAMES.index("left_wrist")]
    forearm = body.weights[:, JOINT_NAMES.index("left_elbow")] > 0.95
    v = body.v_template.double()
    moved = v + 0.02 * vertex_normals(body.v_template, body.faces)

    def radius(p):
        p = p[forearm] - a
        axis = (b - a) / (b - a).norm()
        return (p - (p @ axis)[:, None] * axis).norm(dim=1)

    grown = radius(moved) - radius(v)
    assert forearm.sum() > 20 and 0.017 < float(grown.median()) < 0.021


def test_posing_is_linear_in_the_offsets(body):
    """The surface moved along its rest normals, then posed, is the posed surface moved along
    the posed normals by the same amounts."""
    g = torch.Generator().manual_seed(0)
    poses = 0.4 * torch.randn(3, body.num_joints, 3, generator=g, dtype=torch.float64)
    trans = torch.randn(3, 3, generator=g, dtype=torch.float64)
    offsets = np.linspace(0.06, -0.01, body.num_joints)
    verts, normals = posed_normals(body, poses, trans)
    along = vertex_offsets(body, offsets)
    expected = verts + normals * along[None, :, None]
    moved = copy.copy(body)
    moved.v_template = (
        body.v_template.double() + along[:, None] * vertex_normals(body.v_template, body.faces)
    ).float()
    posed = moved.forward(poses.float(), trans.float()).vertices.double()
    assert torch.allclose(posed, expected, atol=2e-5)


def test_left_and_right_joints_share_an_offset():
    groups = symmetric_groups(JOINT_NAMES)
    assert sorted(i for g in groups for i in g) == list(range(len(JOINT_NAMES)))
    pairs = [g for g in groups if len(g) == 2]
    assert len(pairs) == 9 and len(groups) == 15
    for a, b in pairs:
        assert JOINT_NAMES[a].replace("left_", "") == JOINT_NAMES[b].replace("right_", "")
