"""``texvocab shot``: the viewer's 3D view (and, for a checkpoint, the neural render from
the same camera) for one pose, written as PNGs with no display (moderngl over OSMesa)."""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from texvocab.errors import TexvocabError
from texvocab.pipeline import POSE_PRESETS as PRESETS
from texvocab.pipeline import (
    contact_sheet,
    load_pose_file,
    march_settings,
    place_motion,
    prepare_shell,
    render_image,
    save_png,
    to_uint8,
)
from texvocab_viewer.arguments import parse_size
from texvocab_viewer.gl.camera import DEFAULT_TARGET, OrbitCamera
from texvocab_viewer.gl.headless import create_headless_context, make_current, release
from texvocab_viewer.gl.scene import SceneOptions, SceneRenderer, as_camera
from texvocab_viewer.state import ViewerData, ViewerState, load_viewer_data

DEFAULT_SIZE = (640, 400)


def _views(state: ViewerState) -> int:
    cap = state.data.capture
    return 0 if cap is None else cap.num_views


def apply_pose(state: ViewerState, spec: str, root: str = "floor", view: int = 0) -> None:
    """Set ``state`` from a preset name, a capture frame index (``N`` or ``frame:N``), or
    ``FILE.npz[:N]`` (poses (T, 24, 3) and optional trans (T, 3)); with a capture, a
    file's motion stands by ``root`` as ``texvocab render --root`` stands it (``facing``
    turns it to capture view ``view``)."""
    cap = state.data.capture
    if spec in PRESETS:
        state.apply_preset(spec)
        return
    frame = spec.split(":", 1)[1] if spec.startswith("frame:") else spec
    if frame.isdigit():
        if cap is None:
            raise TexvocabError(f"--pose {spec}: a frame index needs a capture or checkpoint")
        n = int(frame)
        if n >= cap.num_frames:
            raise TexvocabError(f"--pose {spec}: the capture has frames 0..{cap.num_frames - 1}")
        state.set_pose(cap.poses[n], cap.trans[n])
        return
    path, _, idx = spec.rpartition(":") if ":" in spec and not Path(spec).exists() else (spec, "", "")
    if Path(path).suffix == ".npz":
        poses, trans = load_pose_file(path)
        if not idx.isdigit() and idx:
            raise TexvocabError(f"--pose {spec}: expected FILE.npz:N with a frame number N")
        n = int(idx or 0)
        if n >= len(poses):
            raise TexvocabError(f"--pose {spec}: {path} has poses 0..{len(poses) - 1}")
        if cap is not None:
            pelvis = cap.body.rest_joints[0].double().numpy()
            poses, trans = place_motion(poses, trans, pelvis, cap, cap.cameras[view], root)
        state.set_pose(poses[n], trans[n])
        return
    raise TexvocabError(
        f"--pose {spec!r}: expected a preset ({', '.join(sorted(PRESETS))}), a "
        "capture frame index N (or frame:N) or FILE.npz[:N]"
    )


def parse_camera(spec: str, data: ViewerData, state: ViewerState):
    """A capture view index -> its camera; 'yaw,pitch,distance' (degrees, metres) -> an
    :class:`OrbitCamera` looking at the body centre (default centre + root translation)."""
    if spec.isdigit():
        cap = data.capture
        if cap is None:
            raise TexvocabError(f"--camera {spec}: a view index needs a capture or checkpoint")
        if int(spec) >= cap.num_views:
            raise TexvocabError(f"--camera {spec}: the capture has views 0..{cap.num_views - 1}")
        return cap.cameras[int(spec)]
    try:
        yaw, pitch, dist = (float(v) for v in spec.split(","))
    except ValueError:
        raise TexvocabError(
            f"--camera {spec!r}: expected a capture view index or "
            "'yaw,pitch,distance' (degrees, degrees, metres)"
        ) from None
    if not (np.isfinite([yaw, pitch, dist]).all() and dist > 0 and abs(pitch) < 90):
        raise TexvocabError(f"--camera {spec!r}: need distance > 0 and |pitch| < 90")
    return OrbitCamera(target=np.asarray(DEFAULT_TARGET) + state.trans, yaw=yaw, pitch=pitch, distance=dist)


@dataclass
class Shot:
    """view3d: (H, W, 3) uint8 GL view; neural: (H, W, 3) uint8 or None; seconds each."""

    view3d: np.ndarray
    neural: np.ndarray | None
    gl_seconds: float
    neural_seconds: float = 0.0


def render_neural(model, march, pose, trans, camera, background, cancelled=None) -> np.ndarray:
    """(H, W, 3) uint8 render of the trained field ``model`` at ``pose`` (24, 3) and
    ``trans`` (3,), seen by ``camera`` (an OpenCV Camera), with ``march`` settings, over
    ``background`` (the 3D view's): what ``shot`` and the viewer's exports write.
    ``cancelled()`` is checked between ray chunks (:func:`texvocab.render.render_image`)."""
    with torch.no_grad():
        ctx = model.pose_feature.context(pose, trans)
        shell = prepare_shell(march, ctx.vertices, model.body.faces, ctx.index)  # its path's
        out = render_image(
            model.for_pose(ctx, march.precision),
            camera,
            ctx.vertices,
            model.body.faces,
            march,
            background=tuple(background),
            shell=shell,
            index=ctx.index,
            cancelled=cancelled,
        )
    return to_uint8(out.rgb.numpy())


def take_shot(
    data: ViewerData,
    state: ViewerState,
    camera,
    size: tuple[int, int],
    options: SceneOptions,
    neural: bool,
    ctx=None,
) -> Shot:
    """Render the 3D view (on ``ctx``, or a fresh OSMesa context released afterwards) and,
    when ``neural`` and a model is loaded, the neural render from the same camera."""
    own = ctx is None
    ctx = create_headless_context() if own else ctx
    t0 = time.perf_counter()
    try:
        if own:
            make_current(ctx)
        renderer = SceneRenderer(ctx, data)
        renderer.render(state, camera, size, options)
        view = renderer.read(size)
        renderer.release()
    finally:
        if own:
            release(ctx)
    shot = Shot(view, None, time.perf_counter() - t0)
    if neural and data.model is not None:
        t0 = time.perf_counter()
        shot.neural = render_neural(
            data.model,
            march_settings(data.settings),
            state.pose,
            state.trans,
            as_camera(camera, *size),
            options.background,
        )
        shot.neural_seconds = time.perf_counter() - t0
    return shot


def write_shot(out: str | Path, shot: Shot) -> list[Path]:
    """view3d.png, neural.png (if any) and shot.png (side by side, labelled) under ``out``."""
    out = Path(out)
    paths = [save_png(out / "view3d.png", shot.view3d)]
    tiles, labels = [shot.view3d], ["3D view (GL)"]
    if shot.neural is not None:
        paths.append(save_png(out / "neural.png", shot.neural))
        tiles.append(shot.neural)
        labels.append("neural render")
    paths.append(save_png(out / "shot.png", contact_sheet([tiles], col_labels=labels)))
    return paths


def cmd_shot(args: argparse.Namespace) -> int:
    if args.neural and args.source is None:
        raise TexvocabError("--neural needs a checkpoint (SOURCE = checkpoint.pt)")
    if args.size is not None:
        parse_size(args.size)  # a bad size is refused before the avatar loads
    data = load_viewer_data(args.source, args.smpl, args.capture, args.other_capture)
    if args.neural and data.model is None:
        raise TexvocabError(f"--neural: {args.source} is a capture, not a checkpoint")
    state = ViewerState(data)
    view = int(args.camera) if str(args.camera).isdigit() and state.data.capture is not None else 0
    apply_pose(state, args.pose, getattr(args, "root", "floor"), min(view, max(0, _views(state) - 1)))
    camera = parse_camera(args.camera, data, state)
    if args.size is not None:
        size = parse_size(args.size)
    elif hasattr(camera, "width"):
        size = (camera.width, camera.height)
    else:
        size = DEFAULT_SIZE
    try:
        as_camera(camera, *size)
    except ValueError as exc:
        raise TexvocabError(f"--size {args.size}: {exc}") from None
    options = SceneOptions(**{name: True for name in args.overlay})
    shot = take_shot(data, state, camera, size, options, neural=args.neural is not False)
    paths = write_shot(args.out, shot)
    print(
        f"3D view {size[0]}x{size[1]} in {shot.gl_seconds:.2f} s"
        + (f", neural render in {shot.neural_seconds:.2f} s" if shot.neural is not None else "")
    )
    for p in paths:
        print(f"  {p.resolve()}")
    return 0


DEMO_LOOKS = (
    ("3D view: vocabulary texture", {}),
    ("part colours", {"part_colors": True}),
    ("novelty + skeleton", {"novelty": True, "skeleton": True}),
)


def demo_shots(
    source: str | Path,
    out_dir: str | Path,
    poses: tuple[str, ...] | None = None,
    view: int = 1,
    smpl: str | None = None,
) -> Path:
    """What the viewer would show, for a display-less demo: for each pose (default: the
    last novel frame of the capture, then 'kick' and 'arms_up'), the 3D view textured,
    with part colours and with the novelty overlay, and the neural render (checkpoints),
    all from the capture's held-out ``view``. Writes one shot folder per pose and a
    contact sheet ``viewer_shots.png`` under ``out_dir``; returns the sheet's path."""
    data = load_viewer_data(str(source), smpl=smpl)
    cap = data.capture
    if poses is None:
        poses = ((str(cap.num_frames - 1),) if cap is not None else ()) + ("kick", "arms_up")
    out = Path(out_dir)
    ctx = create_headless_context()
    rows, row_labels = [], []
    try:
        make_current(ctx)
        for spec in poses:
            state = ViewerState(data)
            apply_pose(state, spec)
            camera = cap.cameras[view] if cap is not None else parse_camera("0,10,3.0", data, state)
            size = (camera.width, camera.height)
            tiles = []
            for i, (_, flags) in enumerate(DEMO_LOOKS):
                shot = take_shot(data, state, camera, size, SceneOptions(**flags), neural=i == 0, ctx=ctx)
                if i == 0:
                    write_shot(out / f"pose_{spec}", shot)
                    neural = shot.neural
                tiles.append(shot.view3d)
            if neural is not None:
                tiles.append(neural)
            rows.append(tiles)
            row_labels.append(f"frame {spec}" if spec.isdigit() else spec)
    finally:
        release(ctx)
    cols = [label for label, _ in DEMO_LOOKS] + (["neural render"] if data.model is not None else [])
    return save_png(out / "viewer_shots.png", contact_sheet(rows, row_labels, cols))
