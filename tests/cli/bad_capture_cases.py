"""Bad captures and sizes for the front door's table (test_cli_bad_input.py), by class:
damaged image and mask files (garbage, a format captures do not use, a decompression bomb,
a file cut short), calibration that cannot be a camera, masks that are all empty or all
full, and sizes and frame rates beyond their stated limits. Each case is (id, argv builder,
words of the error line); builders copy the world's capture and change the copy."""

import shutil
import zipfile

import numpy as np
from bad_files import garbage, gif_bytes, png_declaring, truncated
from PIL import Image


def _copy(world, name, change):
    dst = world / "bad" / name
    if not dst.exists():
        shutil.copytree(world / "cap", dst, ignore=shutil.ignore_patterns("texvocab_cache"))
        change(dst)
    return str(dst)


def _overwrite(folder: str, data):
    """Replace frame 1 of view 2's image (or mask) with ``data`` (bytes or a function of the
    file's bytes)."""

    def change(root):
        path = root / folder / "Camera_B3" / "000001.png"
        path.write_bytes(data(path.read_bytes()) if callable(data) else data)

    return change


def _cams(edit):
    """Apply ``edit(cams, view)`` to view 0 of annots.npy."""

    def change(root):
        annots = np.load(root / "annots.npy", allow_pickle=True).item()
        cams = annots["cams"]
        for key in ("K", "R", "T", "D"):
            cams[key] = [np.array(a, dtype=np.float64) for a in cams[key]]
        edit(cams)
        np.save(root / "annots.npy", annots, allow_pickle=True)

    return change


def _set(key, index, value):
    """Set entry ``index`` of view 0's ``key`` in annots.npy."""

    def edit(cams):
        cams[key][0][index] = value

    return _cams(edit)


def _turn_away(cams):
    flip = np.diag([1.0, -1.0, -1.0])  # half a turn about the camera's x axis, in place
    cams["R"][0] = flip @ cams["R"][0]
    cams["T"][0] = flip @ cams["T"][0]


def _scale_t(cams):
    cams["T"][0] = cams["T"][0] * 1e12


def _th_string(root):
    path = root / "params" / "1.npy"
    params = np.load(path, allow_pickle=True).item()
    params["Th"] = "abc"
    np.save(path, params, allow_pickle=True)


def _all_masks(value):
    def change(root):
        for path in (root / "mask").rglob("*.png"):
            with Image.open(path) as im:
                Image.new(im.mode, im.size, value).save(path)

    return change


def _pose_file(world, name, **arrays):
    path = world / "bad" / name
    path.parent.mkdir(exist_ok=True)
    np.savez(path, **arrays)
    return str(path)


def _lying_header(world):
    """A pose file whose 'poses' header declares 10^9 frames over 2 frames of data."""
    path = world / "bad" / "liar.npz"
    path.parent.mkdir(exist_ok=True)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive, archive.open("poses.npy", "w") as fh:
        header = {"descr": "<f8", "fortran_order": False, "shape": (10**9, 72)}
        np.lib.format.write_array_header_1_0(fh, header)
        fh.write(bytes(2 * 72 * 8))
    return str(path)


def _train(name, change):
    return lambda w: ["train", _copy(w, name, change), "--out", str(w / "new_run"), "--set", "num_keys=3"]


def _vocab(name, change):
    return lambda w: ["vocab", _copy(w, name, change), "--pose", "frame:0"]


def _sheet(name, change, *extra):
    return lambda w: ["contact-sheet", _copy(w, name, change), "--out", str(w / "sheet.png"), *extra]


AMASS_TINY_RATE = {"poses": np.zeros((3, 156)), "mocap_framerate": np.array(1e-4)}
AMASS_STRING_RATE = {"poses": np.zeros((3, 156)), "mocap_framerate": np.array("fast")}
PIXEL_LIMIT = "over the limit of 40 Mpx"

CAPTURE_CASES = [
    # damaged files: the header is checked before any long work, decoding finds the rest
    ("image-garbage", _train("img_junk", _overwrite("", garbage())), "000001.png: not a readable image"),
    ("image-gif", _train("img_gif", _overwrite("", gif_bytes((64, 64)))), "expected a PNG or JPEG"),
    ("image-bomb", _train("img_bomb", _overwrite("", png_declaring(100_000, 100_000))), PIXEL_LIMIT),
    ("mask-garbage", _train("mask_junk", _overwrite("mask", garbage())), "not a readable mask"),
    ("mask-bomb", _train("mask_bomb", _overwrite("mask", png_declaring(100_000, 100_000))), PIXEL_LIMIT),
    ("image-truncated", _sheet("img_cut", _overwrite("", truncated)), "(truncated or damaged)"),
    (
        "mask-truncated",
        _sheet("mask_cut", _overwrite("mask", truncated), "--masks"),
        "(truncated or damaged)",
    ),
    # calibration that cannot be a camera, named by annots.npy's field
    ("calib-K-last-row-zero", _vocab("k_row", _set("K", 2, 0.0)), "cams['K'][0]: last row"),
    ("calib-K-lower-triangle", _vocab("k_low", _set("K", (1, 0), 3.0)), "upper-triangular"),
    ("calib-focal-negative", _vocab("k_neg", _set("K", (0, 0), -50.0)), "expected both between"),
    ("calib-skew-1e6", _vocab("skew", _set("K", (0, 1), 1e6)), "skew K[0][1] = 1e+06 px"),
    ("calib-distortion-1e6", _vocab("dist", _set("D", 0, 1e6)), "cams['D'][0]: "),
    ("calib-R-not-rotation", _vocab("r_scaled", _set("R", (0, 0), 3.0)), "cams['R'][0]: is not a rotation"),
    ("calib-facing-away", _vocab("away", _cams(_turn_away)), "does not see the subject"),
    ("calib-T-1e12", _vocab("far", _cams(_scale_t)), "m away; expected it 0.05..100 m in front"),
    ("params-Th-string", _vocab("th_str", _th_string), "1.npy: 'Th' is a str; expected numbers"),
    # masks that cannot be a silhouette
    ("masks-all-empty", _vocab("m_empty", _all_masks(0)), "all 30 masks are empty"),
    ("masks-all-full", _vocab("m_full", _all_masks(255)), "all 30 masks are full"),
    # sizes and frame rates, each with its stated limit
    (
        "synth-size-huge",
        ["synth", "{base}/new_cap", "--size", "100000"],
        "--size 100000: expected at least 1 and at most 4096",
    ),
    ("synth-texture-size-huge", ["synth", "{base}/new_cap", "--texture-size", "100000"], "at most 4096"),
    ("synth-ring-views-huge", ["synth", "{base}/new_cap", "--ring-views", "1000000"], "at most 64"),
    (
        "demo-size-huge",
        ["demo", "--out", "{base}/demo", "--size", "100000"],
        "--size 100000: expected a tile",
    ),
    ("prepare-texture-size-huge", ["prepare", "{cap}", "--texture-size", "100000"], "texture_size"),
    (
        "render-fps-huge",
        lambda w: [
            "render",
            str(w / "run" / "checkpoint.pt"),
            "--poses",
            _pose_file(w, "still2.npz", poses=np.zeros((2, 72))),
            "--fps",
            "1e9",
            "--out",
            str(w / "x.mp4"),
        ],
        "--fps 1e+09: expected a frame rate in (0, 1000]",
    ),
    (
        "synth-poses-rate-tiny",
        lambda w: ["synth", str(w / "new_cap"), "--poses", _pose_file(w, "slow.npz", **AMASS_TINY_RATE)],
        "expected at most 36000",
    ),
    (
        "synth-poses-rate-string",
        lambda w: ["synth", str(w / "new_cap"), "--poses", _pose_file(w, "str.npz", **AMASS_STRING_RATE)],
        "'mocap_framerate' is ['fast']",
    ),
    (
        "synth-poses-header-declares-1e9-frames",
        lambda w: ["synth", str(w / "new_cap"), "--poses", _lying_header(w)],
        "liar.npz: array 'poses' declares (1000000000, 72) float64",
    ),
]
