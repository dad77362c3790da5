"""VideoSink: an MP4 that opens on the first frame, is readable by another decoder, and states why it cannot open."""

import imageio.v3 as iio
import numpy as np
import pytest

from simreal_nodes.io.video import VideoSink


def test_writes_a_readable_mp4(tmp_path):
    path = tmp_path / "sub" / "overlay.mp4"  # the folder is made on the first frame
    sink = VideoSink(str(path), 10.0)
    assert sink.writer is None and not path.exists()
    for k in range(12):
        frame = np.zeros((48, 64, 3), np.uint8)
        frame[:, : 5 * (k + 1)] = (0, 0, 255)  # a red bar (BGR) that grows frame by frame
        sink.write(frame)
    sink.close()
    sink.close()  # closing twice is harmless
    assert sink.frames == 12
    video = iio.imread(path)
    assert video.shape[0] == 12 and video.shape[1:3] == (48, 64)
    last = video[-1].astype(int)
    # RGB now: the bar is red, the rest black (lossy codec: loose bounds)
    assert last[24, 30, 0] > 180 and last[24, 30, 2] < 80 and last[24, 63].max() < 60


def test_unopenable_path_raises(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    sink = VideoSink(str(blocker / "x.mp4"), 10.0)  # the parent is a file: no folder, no writer
    with pytest.raises(OSError):
        sink.write(np.zeros((8, 8, 3), np.uint8))
