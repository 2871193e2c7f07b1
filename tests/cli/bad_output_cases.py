"""Outputs that cannot be written, for the front door's table (test_cli_bad_input.py), by
class: an ``--out`` on a read-only mount for each command that writes one, and an
``--out`` of the wrong kind (a file where a folder is expected, a folder where a file
is). Each case is (id, argv builder, words of the error line)."""

import shutil

from readonly_mount import read_only_folder

RO = "read-only file system"


def _ro(world) -> str:
    """world/ro: a read-only folder holding one file, one folder and a copy of the run."""

    def fill(folder):
        (folder / "a_file").write_bytes(b"x")
        (folder / "a_folder.mp4").mkdir()
        shutil.copytree(world / "run", folder / "run")

    return str(read_only_folder(world / "ro", fill))


def _file(world) -> str:
    path = world / "bad" / "plain_file"
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(b"x")
    return str(path)


def _ckpt(world) -> str:
    return str(world / "run" / "checkpoint.pt")


def _poses(world) -> str:
    import numpy as np

    path = world / "bad" / "still_out.npz"
    path.parent.mkdir(exist_ok=True)
    np.savez(path, poses=np.zeros((2, 72)))
    return str(path)


OUTPUT_CASES = [
    ("out-ro-synth", lambda w: ["synth", _ro(w) + "/cap", "--frames", "1"], RO),
    ("out-ro-synth-nested", lambda w: ["synth", _ro(w) + "/a/b/cap", "--frames", "1"], RO),
    ("out-ro-train", lambda w: ["train", str(w / "cap"), "--out", _ro(w) + "/new_run"], RO),
    ("out-ro-eval", lambda w: ["eval", _ckpt(w), str(w / "cap"), "--out", _ro(w) + "/eval"], RO),
    (
        "out-ro-eval-default",
        lambda w: ["eval", _ro(w) + "/run/checkpoint.pt", str(w / "cap")],
        "report folder (choose one with --out)",
    ),
    (
        "out-ro-render-mp4",
        lambda w: ["render", _ckpt(w), "--poses", _poses(w), "--out", _ro(w) + "/clip.mp4"],
        RO,
    ),
    (
        "out-ro-render-frames",
        lambda w: ["render", _ckpt(w), "--poses", _poses(w), "--out", _ro(w) + "/frames"],
        RO,
    ),
    ("out-ro-contact-sheet", lambda w: ["contact-sheet", str(w / "cap"), "--out", _ro(w) + "/s.png"], RO),
    ("out-ro-shot", lambda w: ["shot", _ckpt(w), "--out", _ro(w) + "/shots"], RO),
    ("out-ro-demo", lambda w: ["demo", "--out", _ro(w) + "/demo", "--train-minutes", "0"], RO),
    ("out-file-synth", lambda w: ["synth", _file(w), "--frames", "1"], "is a file; expected a folder"),
    ("out-file-eval", lambda w: ["eval", _ckpt(w), str(w / "cap"), "--out", _file(w)], "is a file"),
    (
        "out-file-render-frames",
        lambda w: ["render", _ckpt(w), "--poses", _poses(w), "--out", _file(w)],
        "is a file; expected a folder",
    ),
    (
        "out-folder-render-mp4",
        lambda w: ["render", _ckpt(w), "--poses", _poses(w), "--out", _ro(w) + "/a_folder.mp4"],
        "is a folder; expected a file",
    ),
    (
        "out-folder-contact-sheet",
        lambda w: ["contact-sheet", str(w / "cap"), "--out", str(w / "run")],
        "is a folder; expected a file",
    ),
    ("out-file-shot", lambda w: ["shot", _ckpt(w), "--out", _file(w)], "is a file; expected a folder"),
    (
        "out-under-a-file",
        lambda w: ["train", str(w / "cap"), "--out", _file(w) + "/run"],
        "is a file, so no folder can be made there",
    ),
]
