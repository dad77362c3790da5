"""Frames rendered one at a time (synth.sequence.FrameStream) for sequences too long to hold, and the long room."""

import numpy as np
import pytest

from simreal_nodes.synth.makebag import make_scene
from simreal_nodes.synth.sequence import FrameStream, sequence


def test_a_stream_gives_the_frames_of_the_sequence_noise_included():
    seq = sequence("slam_room", 64, 48, stereo=True, frames=3, ssaa=1, seed=2)
    fs = FrameStream("slam_room", 64, 48, stereo=True, frames=3, ssaa=1, seed=2)
    assert fs.n == 3 and fs.cam.width == 64
    frames = list(fs)
    assert len(frames) == 3
    for i, f in enumerate(frames):
        for k in ("rgb", "gray", "right", "T"):
            assert np.array_equal(f[k], seq[k][i]), k
        assert np.array_equal(f["depth"], seq["depth"][i], equal_nan=True)
    with pytest.raises(RuntimeError, match="once"):
        next(iter(fs))
    # another seed draws other noise on the same picture
    other = next(iter(FrameStream("slam_room", 64, 48, frames=1, ssaa=1, seed=3)))
    assert not np.array_equal(other["rgb"], frames[0]["rgb"])
    assert np.array_equal(other["T"], frames[0]["T"])


def test_the_long_room_repeats_its_lap():
    """slam_room_laps: the 10 s there-and-back lap over 70 s: the camera is back where it started after each lap
    (within the hand-held jitter), half a lap later at the arc's far end."""
    sc = make_scene("slam_room_laps", 64, 48)
    assert round(sc.duration * sc.fps) == 2100
    p = [sc.camera_pose(t)[:3, 3] for t in (0.0, 10.0, 60.0, 5.0)]
    assert np.linalg.norm(p[1] - p[0]) < 0.05 and np.linalg.norm(p[2] - p[0]) < 0.05
    assert np.linalg.norm(p[3] - p[0]) > 0.5
