import numpy as np
import pytest

from simreal_nodes.errors import ImageFormatError
from simreal_nodes.io import images


class Msg:
    def __init__(self, h, w, enc, step, data, be=0):
        self.height, self.width, self.encoding, self.step, self.data, self.is_bigendian = h, w, enc, step, data, be


@pytest.mark.parametrize("enc,dtype,c", [("rgb8", np.uint8, 3), ("mono8", np.uint8, 1), ("16UC1", np.uint16, 1),
                                         ("32FC1", np.float32, 1), ("bgra8", np.uint8, 4)])
def test_round_trip(enc, dtype, c):
    rng = np.random.default_rng(0)
    shape = (7, 9, c) if c > 1 else (7, 9)
    img = (rng.random(shape) * 200).astype(dtype)
    f = images.array_to_image_fields(img, enc)
    back = images.image_to_array(Msg(f.height, f.width, f.encoding, f.step, f.data))
    np.testing.assert_array_equal(back, img)


def test_row_padding_is_respected():
    img = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    step = 5 * 3 + 4
    buf = np.zeros((4, step), np.uint8)
    buf[:, :15] = img.reshape(4, 15)
    out = images.image_to_array(Msg(4, 5, "rgb8", step, buf.tobytes()))
    np.testing.assert_array_equal(out, img)


def test_big_endian_16bit():
    img = np.array([[1, 256, 4000]], np.uint16)
    out = images.image_to_array(Msg(1, 3, "16UC1", 6, img.astype(">u2").tobytes(), be=1))
    np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize("h,w,enc,step,n,match", [
    (4, 5, "rgb8", 14, 60, "step 14 is smaller"),
    (4, 5, "rgb8", 15, 59, "data has 59 bytes"),
    (4, 5, "rgb8", 15, 61, "more than height"),
    (4, 5, "yuv9000", 15, 60, "not supported"),
    (0, 5, "rgb8", 15, 0, "empty"),
])
def test_disagreeing_fields_give_clear_errors(h, w, enc, step, n, match):
    with pytest.raises(ImageFormatError, match=match):
        images.image_to_array(Msg(h, w, enc, step, bytes(n)))


def test_depth_conversion_marks_invalid():
    mm = np.array([[0, 1500, 65535]], np.uint16)
    d = images.depth_to_metres(mm, "16UC1")
    assert np.isnan(d[0, 0]) and d[0, 1] == pytest.approx(1.5)
    m = np.array([[np.nan, np.inf, -1.0, 0.0, 2.5]], np.float32)
    d = images.depth_to_metres(m, "32FC1")
    assert np.isnan(d[0, :4]).all() and d[0, 4] == pytest.approx(2.5)
    with pytest.raises(ImageFormatError, match="depth encoding"):
        images.depth_to_metres(m, "rgb8")
