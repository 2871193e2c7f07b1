"""Calibration that must be a camera, for every layout's reader: the intrinsics a pinhole
camera can have, a rotation, a lens whose distortion stays within the image, an image size
within the pixel limit, and a view that sees the subject. Each refusal is one
:class:`~texvocab.errors.AssetError` naming the file, the field (as that file names it) and
what was expected.

The limits (module constants) are generous for real cameras and far from what a mistake
gives (a zero row in K, a 1e6 skew or distortion, a camera facing away, T in the wrong unit).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from texvocab.capture.camera import Camera
from texvocab.capture.image_reader import MAX_PIXELS
from texvocab.errors import AssetError

log = logging.getLogger("texvocab")

#: |K[0, 1]| (skew) at most this fraction of the focal length fx.
MAX_SKEW = 0.1
#: fx and fy at most this many times the image's longest side (a 1000 mm lens on a
#: full-frame 8K sensor is about 28 times).
MAX_FOCAL_SIDES = 100.0
#: ... and at least this fraction of it (a pinhole seeing 180° has fx near 0; below this,
#: rays are numerically degenerate: fx = 1e-308 gave NaN directions).
MIN_FOCAL_SIDES = 0.01
#: The lens model may move no pixel of the image by more than this fraction of its diagonal.
MAX_DISTORTION_SHIFT = 0.25
#: The subject's centre must be this far in front of a camera, in metres.
MIN_DEPTH, MAX_DEPTH = 0.05, 100.0
#: Tolerance of the fixed entries of K (its zeros and K[2, 2] = 1) and of R's orthonormality.
K_TOL, R_TOL = 1e-6, 1e-3
#: Below this share of frames seeing the subject a camera gets a warning line.
SEEN_SHARE_WARNING = 0.5


@dataclass(frozen=True)
class CameraFields:
    """How a calibration file names one camera's fields, for the error lines
    (e.g. ZJU-MoCap ``cams['K'][3]``, THUman4.0 ``cam03 'K'``)."""

    K: str
    R: str
    t: str
    dist: str
    size: str

    @classmethod
    def keyed(cls, prefix: str, K: str, R: str, t: str, dist: str, size: str) -> CameraFields:
        """Each name as ``<prefix><key>``."""
        return cls(*(f"{prefix}{k}" for k in (K, R, t, dist, size)))


def _fail(source: str, cam: Camera, field: str, problem: str) -> AssetError:
    return AssetError(f"{source}: camera {cam.name!r} {field}: {problem}")


def check_camera(cam: Camera, source: str, fields: CameraFields) -> Camera:
    """``cam`` when its calibration can be a camera (module docstring), else AssetError
    naming ``source`` and the field."""
    for key, name in (("K", fields.K), ("R", fields.R), ("t", fields.t), ("dist", fields.dist)):
        if not np.isfinite(getattr(cam, key)).all():
            raise _fail(source, cam, name, "holds NaN or inf; expected finite numbers")
    w, h = cam.width, cam.height
    if w < 1 or h < 1 or w * h > MAX_PIXELS:
        raise _fail(
            source, cam, fields.size, f"{w}x{h}; expected at least 1x1 and at most {MAX_PIXELS / 1e6:.0f} Mpx"
        )
    _check_intrinsics(cam, source, fields.K)
    R = cam.R
    if np.abs(R @ R.T - np.eye(3)).max() > R_TOL or np.linalg.det(R) < 0:
        raise _fail(
            source,
            cam,
            fields.R,
            f"is not a rotation (|R R^T - I| = {np.abs(R @ R.T - np.eye(3)).max():.3g}, det "
            f"{np.linalg.det(R):.3g}); expected an orthonormal world-to-camera rotation, det +1",
        )
    _check_distortion(cam, source, fields.dist)
    return cam


def _check_intrinsics(cam: Camera, source: str, field: str) -> None:
    K = cam.K
    fx, fy, skew = K[0, 0], K[1, 1], K[0, 1]
    if np.abs(K[2] - (0.0, 0.0, 1.0)).max() > K_TOL:
        raise _fail(source, cam, field, f"last row is {K[2].tolist()}; expected (0, 0, 1)")
    if abs(K[1, 0]) > K_TOL * max(1.0, abs(fy)):
        raise _fail(source, cam, field, f"K[1][0] is {K[1, 0]:g}; expected 0 (K is upper-triangular)")
    side = max(cam.width, cam.height)
    lo, hi = MIN_FOCAL_SIDES * side, MAX_FOCAL_SIDES * side
    if not (lo <= fx <= hi and lo <= fy <= hi):
        raise _fail(
            source,
            cam,
            field,
            f"focal lengths {fx:g}, {fy:g} px; expected both between {MIN_FOCAL_SIDES:g} and "
            f"{MAX_FOCAL_SIDES:g} x the image's longest side ({lo:g} to {hi:g} px)",
        )
    if abs(skew) > MAX_SKEW * fx:
        raise _fail(
            source,
            cam,
            field,
            f"skew K[0][1] = {skew:g} px; expected at most {MAX_SKEW:g} x fx ({MAX_SKEW * fx:g})",
        )


def _check_distortion(cam: Camera, source: str, field: str) -> None:
    """The distortion moves no pixel of a 17 x 17 grid over the image by more than
    ``MAX_DISTORTION_SHIFT`` of the diagonal, and the radial model does not fold back
    (its distorted radius grows) out to the image's farthest corner."""
    if not np.any(cam.dist):
        return
    K = cam.K
    xs, ys = np.meshgrid(np.linspace(0, cam.width - 1, 17), np.linspace(0, cam.height - 1, 17))
    xy = np.stack([(xs.ravel() - K[0, 2]) / K[0, 0], (ys.ravel() - K[1, 2]) / K[1, 1]], -1)
    with np.errstate(all="ignore"):
        moved = cam.distort_normalized(xy) * (K[0, 0], K[1, 1])
        shift = np.linalg.norm(moved - xy * (K[0, 0], K[1, 1]), axis=-1).max()
        r = np.linspace(0.0, np.linalg.norm(xy, axis=-1).max(), 64)
        k1, k2, _, _, k3 = cam.dist
        radial = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    diagonal = float(np.hypot(cam.width, cam.height))
    folds = not np.isfinite(radial).all() or (np.diff(radial) <= 0).any()
    if not np.isfinite(shift) or shift > MAX_DISTORTION_SHIFT * diagonal or folds:
        raise _fail(
            source,
            cam,
            field,
            f"{cam.dist.tolist()} moves pixels by up to {shift:.3g} px"
            f"{' and folds the image back' if folds else ''}; expected a lens model that moves "
            f"none by more than {MAX_DISTORTION_SHIFT:g} of the image diagonal "
            f"({MAX_DISTORTION_SHIFT * diagonal:.0f} px) and keeps the image in order",
        )


def subject_centres(capture) -> np.ndarray:
    """(T, 3) world position of the posed body's centre (its pelvis: the body's rest
    pelvis, with the capture's shape, plus the root translation) in every frame."""
    shape = capture.shape()
    if shape is None:
        pelvis = capture.body.rest_joints[0]
    else:
        pelvis = capture.body.shaped(shape.to(capture.body.dtype), 1)[1][0, 0]
    return pelvis.double().numpy() + np.asarray(capture.trans, np.float64)


def check_views_see_subject(capture, source: str, fields: list[CameraFields]) -> None:
    """Every camera of ``capture`` sees its subject: in at least one frame the body's centre
    is ``MIN_DEPTH``..``MAX_DEPTH`` in front of it and projects inside its image (a warning
    line names a camera that sees it in under half of the frames); else AssetError naming
    the camera's R and t fields in ``source``."""
    centres = subject_centres(capture)
    for cam, names in zip(capture.cameras, fields):
        uv, z = cam.project(centres)
        with np.errstate(invalid="ignore"):
            inside = (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
            seen = (z >= MIN_DEPTH) & (z <= MAX_DEPTH) & inside
        if seen.any():
            if seen.mean() < SEEN_SHARE_WARNING:
                log.warning(
                    "%s: camera %r sees the subject's centre in only %d of %d frames",
                    source,
                    cam.name,
                    int(seen.sum()),
                    len(seen),
                )
            continue
        t = int(np.argsort(z)[len(z) // 2])  # the median frame by depth
        if z[t] < MIN_DEPTH:
            why = f"is {-z[t]:.3g} m behind it" if z[t] < 0 else f"is {z[t]:.3g} m in front of it"
        elif z[t] > MAX_DEPTH:
            why = f"is {z[t]:.3g} m away"
        else:
            pixel = f"({uv[t, 0]:.0f}, {uv[t, 1]:.0f})"
            why = f"projects to pixel {pixel}, outside its {cam.width}x{cam.height} image"
        raise AssetError(
            f"{source}: camera {cam.name!r} ({names.R}, {names.t}) does not see the subject "
            f"in any of the {len(z)} frames: the body's centre at frame {capture.frame_ids[t]} "
            f"{why}; expected it {MIN_DEPTH:g}..{MAX_DEPTH:g} m in front of the camera and "
            "inside the image (check the camera's rotation and translation, its unit, and "
            "the poses' translation)"
        )
