"""``texvocab check-assets``: SMPL model and UV files, or a capture folder, against
assets_spec/ (the spec checks themselves are :mod:`texvocab.io.spec`)."""
from __future__ import annotations

from pathlib import Path

from PIL import Image

from texvocab.body import smpl_io
from texvocab.capture import open as open_capture
from texvocab.errors import AssetError
from texvocab.io.spec import check_arrays, load_spec, name_is_accepted, spec_ref


def check_path(path: str | Path) -> list[str]:
    """Validate a file or folder of user assets; returns report lines ("OK ..." or problems)."""
    path = Path(path)
    if not path.exists():
        raise AssetError(f"{path}: no such file or folder")
    if path.is_dir() and ((path / "annots.npy").is_file() or (path / "calibration.json").is_file()):
        return check_capture(path)
    files = [path] if path.is_file() else sorted(
        p for p in path.rglob("*") if p.suffix in (".pkl", ".npz", ".obj"))
    if not files:
        return [f"{path}: no SMPL model (.pkl/.npz) or UV (.obj) file found; "
                f"see {spec_ref('smpl_model')}"]
    lines = []
    for f in files:
        kind = "smpl_uv" if f.suffix == ".obj" else "smpl_model"
        try:
            arrays = smpl_io.read_uv_obj(f) if kind == "smpl_uv" else smpl_io.read_model_arrays(f)
        except AssetError as exc:
            lines.append(f"FAIL {exc}")
            continue
        problems = check_arrays(arrays, load_spec(kind), str(f))
        if not name_is_accepted(f, load_spec(kind)):
            lines.append(f"note {f}: name is not one of the official names in {spec_ref(kind)}")
        lines += [f"FAIL {p}" for p in problems] or [f"OK   {f}: valid {kind.replace('_', ' ')}"]
    return lines


def check_capture(path: Path) -> list[str]:
    """Open a capture folder and stat every image and mask it lists."""
    try:
        cap = open_capture(path)
    except AssetError as exc:
        return [f"FAIL {exc}"]
    missing = [p for rows in (cap.image_paths, cap.mask_paths) for row in rows for p in row
               if not p.is_file()]
    lines = [f"FAIL {p}: listed by the capture but missing" for p in missing[:10]]
    if len(missing) > 10:
        lines.append(f"FAIL ... and {len(missing) - 10} more missing files")
    for v, cam in enumerate(cap.cameras):
        with Image.open(cap.image_paths[0][v]) as im:
            if im.size != (cam.width, cam.height):
                lines.append(f"FAIL {cap.image_paths[0][v]}: image is {im.size[0]}x{im.size[1]}, "
                             f"calibration says {cam.width}x{cam.height}")
    if not lines:
        lines.append(f"OK   {path}: {cap.layout} capture, {cap.num_views} views x "
                     f"{cap.num_frames} frames ({cap.num_train} training)")
    return lines
