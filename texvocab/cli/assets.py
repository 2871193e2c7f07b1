"""``texvocab check-assets``: SMPL model and UV files, or a capture folder, against
assets_spec/ (the spec checks themselves are :mod:`texvocab.io.spec`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from texvocab.body import smpl_io
from texvocab.capture import detect_layout
from texvocab.capture import open as open_capture
from texvocab.capture.mask_checks import survey_masks
from texvocab.errors import AssetError, PoseError
from texvocab.io.spec import check_arrays, load_spec, name_is_accepted, spec_ref
from texvocab.pipeline.settings import Settings

MAX_LINES = 100  # bad files listed by name; more are counted


def check_path(path: str | Path) -> list[str]:
    """Validate a file or folder of user assets; returns report lines ("OK ..." or problems)."""
    path = Path(path)
    if not path.exists():
        raise AssetError(f"{path}: no such file or folder")
    if path.is_dir() and _is_capture(path):
        return check_capture(path)
    files = (
        [path]
        if path.is_file()
        else sorted(p for p in path.rglob("*") if p.suffix in (".pkl", ".npz", ".obj"))
    )
    if not files:
        return [f"{path}: no SMPL model (.pkl/.npz) or UV (.obj) file found; see {spec_ref('smpl_model')}"]
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


def _is_capture(path: Path) -> bool:
    try:
        detect_layout(path)
    except AssetError:
        return False
    return True


def _check_content(cap) -> list[str]:
    """What training and evaluation rely on beyond the files: poses finite and within the
    stated bounds, the default held-out views present."""
    lines = []
    try:
        cap.body.check_pose(torch.as_tensor(np.asarray(cap.poses)), torch.as_tensor(np.asarray(cap.trans)))
    except PoseError as exc:
        lines.append(f"FAIL {cap.root}: {exc}")
    held_out = [v for v in Settings().data.eval_views if v >= cap.num_views]
    novel = cap.num_frames - cap.num_train
    if cap.num_views == 1:
        held = (
            f"the last {novel} frames ({cap.frame_ids[cap.num_train]}.."
            f"{cap.frame_ids[-1]}) are held out as novel poses, scored from this camera"
            if novel
            else "no frame is held out (every frame trains)"
        )
        lines.append(
            f"note {cap.root}: one camera, so no held-out view: {held}; training "
            "frames are scored as seen views"
        )
    elif held_out:
        lines.append(
            f"note {cap.root}: has views 0..{cap.num_views - 1}, but the default "
            f"eval_views are {list(Settings().data.eval_views)}: train and eval "
            "with --set data.eval_views=... (views that exist)"
        )
    return lines


def _frames_of(cap, where: list[tuple[int, int]]) -> str:
    shown = ", ".join(f"{cap.frame_ids[t]} (view {v})" for t, v in where[: MAX_LINES // 10])
    return shown + (f" and {len(where) - MAX_LINES // 10} more" if len(where) > MAX_LINES // 10 else "")


def _file_lines(cap) -> list[str]:
    """Every image and mask decoded once: a FAIL line per bad file (at most ``MAX_LINES``,
    then a count), a FAIL line for empty masks, a note for full ones."""
    survey = survey_masks(cap)
    problems = cap.image_problems(decode=True, masks=False) + survey.problems
    lines = [f"FAIL {p}" for p in problems[:MAX_LINES]]
    if len(problems) > MAX_LINES:
        lines.append(f"FAIL ... and {len(problems) - MAX_LINES} more bad image or mask files")
    total = cap.num_frames * cap.num_views
    if survey.empty:
        t, v = survey.empty[0]
        lines.append(
            f"FAIL {cap.mask_paths[t][v]}: empty mask ({len(survey.empty)} of {total} masks are "
            f"empty: frames {_frames_of(cap, survey.empty)}); training and evaluation need the "
            "person in every view"
        )
    if survey.full:
        lines.append(
            f"note {cap.root}: {len(survey.full)} of {total} masks are full (every pixel "
            f"foreground): frames {_frames_of(cap, survey.full)}; a mask should be the "
            "person's silhouette"
        )
    return lines


def check_capture(path: Path) -> list[str]:
    """Open a capture folder and decode every image and mask it lists, reporting every bad
    one in one pass."""
    try:
        cap = open_capture(path)
    except AssetError as exc:
        return [f"FAIL {exc}"]
    lines = _file_lines(cap)
    if not [ln for ln in lines if ln.startswith("FAIL")]:
        lines += _check_content(cap)
    if not [ln for ln in lines if ln.startswith("FAIL")]:
        lines += _shell_note(cap)
        lines.append(
            f"OK   {path}: {cap.layout} capture, {cap.num_views} "
            f"view{'s' if cap.num_views != 1 else ''} x "
            f"{cap.num_frames} frames ({cap.num_train} training)"
        )
    return lines


def _shell_note(cap) -> list[str]:
    """A note when the person in the masks reaches farther from the posed body than the
    field's default shell, so training will widen it (texvocab.pipeline.shell_fit)."""
    from texvocab.errors import TexvocabError
    from texvocab.pipeline.model import train_views
    from texvocab.pipeline.shell_fit import fit_shell

    s = Settings()
    try:
        views = train_views(cap, s)
    except TexvocabError:  # held-out views the capture lacks: reported by the content checks
        views = list(range(cap.num_views))
    fitted, fit = fit_shell(cap, s, views)
    if fit is None or fitted.field.shell_width <= s.field.shell_width:
        return []
    return [f"note {cap.root}: {fit.line(s.field.shell_coverage)}"]
