"""Closest point on the posed body (Sec. 3.4, Eq. 7): texvocab.geometry.surface vs trimesh.

Poses the default body, samples points in a thin shell around it (the ray marcher's use)
and far from it, and times ``trimesh.proximity.closest_point`` against
:class:`texvocab.geometry.surface.SurfaceIndex` (its build time reported separately and included in
the total). Prints a Markdown table; timings are the best of ``--repeats`` runs.

    .venv/bin/python bench/projection.py [--points 100000] [--far 10000] [--repeats 3]

trimesh's closest_point needs the ``rtree`` package; without it the trimesh rows are
skipped and accuracy is checked against the brute-force reference only.
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import numpy as np
import torch
import trimesh

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.geometry.surface import SurfaceIndex, project_brute_force


def posed_body(pose_name: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float64, faces (F, 3)) of the default body in a preset pose."""
    body = default_body()
    pose, trans = preset(pose_name)
    out = body.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
    return out.vertices[0].double().numpy(), body.faces.numpy()


def sample_points(
    mesh: trimesh.Trimesh, n: int, near: float, far: float, seed: int, along_normal: bool
) -> np.ndarray:
    """n points (n, 3): surface samples moved by a distance in [near, far] (signed ±far
    along the face normal when ``along_normal``, else in a random direction)."""
    rng = np.random.default_rng(seed)
    pts, fid = trimesh.sample.sample_surface(mesh, n, seed=seed)
    if along_normal:
        return pts + mesh.face_normals[fid] * rng.uniform(-far, far, (n, 1))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return pts + direction * rng.uniform(near, far, (n, 1))


def best_time(fn, repeats: int):
    """(seconds of the fastest run, result of the last run)."""
    best, result = np.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t)
    return best, result


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=100_000, help="shell points (±5 cm)")
    ap.add_argument("--far", type=int, default=10_000, help="far points (5-30 cm)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--pose", default="walk")
    ap.add_argument(
        "--check", type=int, default=2000, help="points also checked against the brute-force reference"
    )
    args = ap.parse_args(argv)

    verts, faces = posed_body(args.pose)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    sets = {
        "shell ±5 cm": sample_points(mesh, args.points, 0.0, 0.05, 0, True),
        "far 5-30 cm": sample_points(mesh, args.far, 0.05, 0.30, 1, False),
    }
    has_rtree = importlib.util.find_spec("rtree") is not None
    index = SurfaceIndex(verts, faces)
    print(
        f"default body, pose {args.pose!r}: {len(verts)} vertices, {len(faces)} faces; "
        f"{index.workers} worker thread(s); best of {args.repeats}\n"
    )

    rows, notes = [], []
    t_build, index = best_time(lambda: SurfaceIndex(verts, faces), args.repeats)
    rows.append(("texvocab SurfaceIndex build (once per posed mesh)", t_build, None, None, None, None))
    for name, pts in sets.items():
        t_ours, ours = best_time(lambda pts=pts: index.project(pts), args.repeats)
        dist = np.abs(ours.distance)
        t_ref = err = None
        if has_rtree:
            t_ref, (cp, d_ref, _) = best_time(
                lambda pts=pts: trimesh.proximity.closest_point(
                    trimesh.Trimesh(verts, faces, process=False), pts
                ),
                args.repeats,
            )
            gap = np.maximum(np.abs(cp - ours.closest).max(1), np.abs(d_ref - dist))
            missed = d_ref - dist > 1e-12  # trimesh returned a farther face
            err = (gap.max(), gap[~missed].max(initial=0.0))
            rows.append((f"trimesh.proximity.closest_point, {name}", t_ref, len(pts), t_ref, None, None))
            differ = np.flatnonzero(gap > 1e-6)
            if len(differ):
                bf = project_brute_force(pts[differ], verts, faces)
                notes.append(
                    f"{name}: {len(differ)} of {len(pts)} points differ from trimesh by more "
                    f"than 1e-6 m ({missed.sum()} where trimesh's face is farther); on them "
                    f"trimesh is farther by {(d_ref[differ] - dist[differ]).min():.1e} to "
                    f"{(d_ref[differ] - dist[differ]).max():.1e} m, never nearer, and "
                    f"texvocab equals brute force to "
                    f"{np.abs(bf.closest - ours.closest[differ]).max():.1e} m"
                )
        check = np.random.default_rng(2).choice(len(pts), min(args.check, len(pts)), False)
        bf = project_brute_force(pts[check], verts, faces)
        bf_err = max(
            np.abs(bf.closest - ours.closest[check]).max(), np.abs(bf.distance - ours.distance[check]).max()
        )
        rows.append((f"texvocab project, {name}", t_ours, len(pts), t_ref, err, bf_err))
        rows.append((f"texvocab build + project, {name}", t_build + t_ours, len(pts), t_ref, err, bf_err))

    print(
        "| method | seconds | points/s | ratio vs trimesh | max error vs trimesh (m): all "
        f"/ where trimesh's face is not farther | max error vs brute force, {args.check} "
        "pts (m) |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for label, sec, n, ref, err, bf_err in rows:
        rate = f"{n / sec:,.0f}" if n else ""
        ratio = f"{ref / sec:.1f}x" if ref else ("" if n is None else "n/a")
        error = (
            "reference"
            if label.startswith("trimesh")
            else ("" if err is None else f"{err[0]:.1e} / {err[1]:.1e}")
        )
        exact = "" if bf_err is None else f"{bf_err:.1e}"
        print(f"| {label} | {sec:.3f} | {rate} | {ratio} | {error} | {exact} |")
    print()
    if not has_rtree:
        print("- trimesh rows skipped: trimesh.proximity.closest_point needs `rtree` (pip install rtree)")
    print(
        "- max error: largest |closest point difference| or |distance difference|. "
        "trimesh treats its two best faces as a tie when their squared distances differ by "
        "less than tol.merge = 1e-8 m² and then keeps the one whose normal faces the point, "
        "which can be the farther face"
    )
    for note in notes:
        print(f"- {note}")


if __name__ == "__main__":
    main()
