"""A trained avatar loaded back from its checkpoint: the model rebuilt on its capture, the
settings it was trained with, and the capture seen with the checkpoint's training split.

Nothing the caller passes is changed: the capture returned is a shallow copy whose
``num_train`` is the checkpoint's (the split its vocabulary and texture maps were built
from), so evaluation and the viewer see the frames the avatar was trained on as training
frames, whatever split the folder's metadata gives today.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import torch

from texvocab.body import load_body
from texvocab.capture import open as open_capture
from texvocab.capture.identity import check_capture_identity
from texvocab.errors import TexvocabError
from texvocab.io.checkpoint import load_checkpoint
from texvocab.method.field import AvatarField
from texvocab.method.vocab import Vocabulary
from texvocab.pipeline.girth_fit import apply_stored_girth
from texvocab.pipeline.model import build_model, load_stored_textures, load_textures
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.shell_fit import apply_stored_shell


@dataclass
class Avatar:
    """``model`` (eval mode), ``settings``, the raw ``checkpoint`` dict and ``capture`` (a
    copy of the given capture with the checkpoint's training split)."""

    model: AvatarField
    settings: Settings
    checkpoint: dict
    capture: object

    @property
    def step(self) -> int:
        return int(self.checkpoint["step"])


def _capture_path(ck: dict, checkpoint: str | Path) -> Path:
    """The capture folder checkpoint dict ``ck`` was trained on; TexvocabError when gone.
    Checkpoints store it absolute; an older relative one is tried from the working folder,
    then from each folder above the checkpoint (where training ran)."""
    recorded = ck.get("capture", "")
    if not isinstance(recorded, str) or not recorded:
        raise TexvocabError(f"{checkpoint}: records no capture folder; pass the capture folder")
    cap_path = Path(recorded)
    candidates = (
        [cap_path]
        if cap_path.is_absolute()
        else ([cap_path] + [p / cap_path for p in Path(checkpoint).resolve().parents])
    )
    for c in candidates:
        if c.is_dir():
            return c
    raise TexvocabError(
        f"{checkpoint}: its capture folder {recorded!r} is missing; the avatar "
        "needs the capture it was trained on (eval: its CAPTURE argument; "
        "shot and view: --capture FOLDER)"
    )


def load_avatar(
    checkpoint: str | Path,
    capture=None,
    smpl: str | None = None,
    progress: bool = True,
    other_capture: bool = False,
) -> Avatar:
    """Rebuild the avatar of ``checkpoint`` on ``capture`` (the one it was trained on);
    None opens the capture folder the checkpoint records, posed by ``smpl`` (None: the
    default body). The checkpoint file is read once. A capture other than the one the
    checkpoint's identity records is refused, or with ``other_capture`` accepted with one
    warning line (:func:`~texvocab.capture.identity.check_capture_identity`)."""
    ck = load_checkpoint(checkpoint)
    if capture is None:
        capture = open_capture(_capture_path(ck, checkpoint), body=load_body(smpl))
    check_capture_identity(ck, capture, checkpoint, other_capture)
    try:
        settings = Settings.from_dict(ck["settings"])
    except TexvocabError as e:
        raise TexvocabError(f"{checkpoint}: {e}") from None
    capture = copy.copy(capture)
    num_train = ck.get("num_train", capture.num_train)
    if type(num_train) is not int or not 1 <= num_train <= capture.num_frames:
        raise TexvocabError(
            f"{checkpoint}: num_train={num_train!r}; expected 1..{capture.num_frames} "
            f"(the frames of {capture.root})"
        )
    capture.num_train = num_train
    try:
        vocab = Vocabulary.from_dict(ck["vocab"])
        vocab.check(capture.num_train)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as e:
        raise TexvocabError(
            f"{checkpoint}: its vocabulary is not readable ({type(e).__name__}: "
            f"{str(e).splitlines()[0] if str(e) else ''})"
        ) from None
    if not isinstance(ck["model"], dict):
        raise TexvocabError(
            f"{checkpoint}: 'model' holds {type(ck['model']).__name__}, expected the weights (a state dict)"
        )
    bad = next(
        (
            k
            for k, v in ck["model"].items()
            if torch.is_tensor(v) and v.is_floating_point() and not torch.isfinite(v).all()
        ),
        None,
    )
    if bad is not None:
        raise TexvocabError(
            f"{checkpoint}: weight {bad} holds NaN or inf (the run diverged); train again, "
            "or resume from an earlier checkpoint"
        )
    textures = load_textures(capture, settings, progress)
    model = build_model(capture, settings, textures, vocab)
    weights = load_stored_textures(model, ck["model"], checkpoint)
    try:
        missing, unexpected = model.load_state_dict(weights, strict=False)
    except RuntimeError as e:
        first = next(
            (ln.strip() for ln in str(e).splitlines() if "size mismatch" in ln), str(e).splitlines()[0]
        )
        raise TexvocabError(
            f"{checkpoint}: weights do not fit the model its settings describe ({first})"
        ) from None
    if unexpected or missing:
        raise TexvocabError(
            f"{checkpoint}: weights do not fit this model (missing "
            f"{missing[:3]}, unexpected {unexpected[:3]})"
        )
    apply_stored_girth(model, ck, checkpoint)
    apply_stored_shell(model, ck, checkpoint)
    model.eval()
    return Avatar(model, settings, ck, capture)
