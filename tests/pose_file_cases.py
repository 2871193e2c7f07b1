"""Shared mocap-file cases: an AMASS-layout file written by the test."""

import numpy as np


def amass_file(path, frames=121, rate=120.0, width=156, rate_key="mocap_framerate"):
    """An AMASS-layout file: a person standing in a Z-up world (root +90° about X, as
    AMASS stores an upright SMPL body), walking 1 m along +X, the left knee bending."""
    t = np.arange(frames) / rate
    poses = np.zeros((frames, width))
    poses[:, 0] = np.pi / 2  # root: upright in Z-up
    poses[:, 3 * 4] = 0.8 * np.sin(2 * np.pi * t)  # left knee (joint 4), about x
    poses[:, 66:] = 0.3  # hands / fingers / face: not SMPL's, must be dropped
    trans = np.stack([t, np.zeros(frames), np.full(frames, 0.95)], 1)
    np.savez(path, poses=poses, trans=trans, betas=np.zeros(16), gender="neutral", **{rate_key: rate})
    return poses, trans
