"""shot --pose FILE.npz:N stands the file's pose by --root as texvocab render does: on a
capture, floor puts its lowest foot on the capture's floor; recorded keeps the file's."""

import numpy as np
import pytest
import torch

from texvocab.body.poses import preset


@pytest.mark.parametrize("root", ["floor", "recorded"])
def test_shot_stands_a_pose_file_by_its_root_choice(capture, tmp_path, root):
    from texvocab.pipeline.clip_placement import place_motion
    from texvocab_viewer.export.shot import apply_pose
    from texvocab_viewer.state import ViewerState, load_viewer_data

    walk, _ = preset("walk")
    poses = np.repeat(np.asarray(walk, np.float32)[None], 3, 0)
    trans = np.array([[2.0, 1.2, -1.5], [2.3, 1.2, -1.5], [2.6, 1.2, -1.5]], np.float32)  # afloat
    np.savez(tmp_path / "walk.npz", poses=poses, trans=trans)
    data = load_viewer_data(str(capture))
    state = ViewerState(data)
    apply_pose(state, f"{tmp_path / 'walk.npz'}:1", root)
    cap = data.capture
    j0 = cap.body.rest_joints[0].double().numpy()
    want_p, want_t = place_motion(poses, trans, j0, cap, cap.cameras[0], root)
    np.testing.assert_allclose(state.trans, want_t[1], atol=1e-6)
    np.testing.assert_allclose(state.pose, want_p[1], atol=1e-6)
    v = cap.body.forward(torch.as_tensor(state.pose[None]), torch.as_tensor(state.trans[None])).vertices
    lowest = float(v[0, :, 1].min())
    floor = float(
        cap.body.forward(
            torch.as_tensor(cap.poses[: cap.num_train]), torch.as_tensor(cap.trans[: cap.num_train])
        )
        .vertices[..., 1]
        .min()
    )
    if root == "floor":
        assert lowest == pytest.approx(floor, abs=0.02)  # frame 1 of a level walk: on the floor
    else:
        np.testing.assert_allclose(state.trans, trans[1], atol=1e-6)
        assert lowest > floor + 1.0  # the file's 1.2 m lift kept
