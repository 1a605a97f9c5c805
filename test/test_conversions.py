"""Tests for hmocap_ros.io.conversions and hmocap_ros.io.msg_factory (both message flavours)."""

from __future__ import annotations

import importlib
import struct

import cv2
import numpy as np
import pytest

from hmocap_ros.io import conversions as conv
from hmocap_ros.io import msg_factory as mf

RNG_SEED = 20240611

ENCODINGS = {
    # encoding: (dtype, channels)
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
    "rgba8": (np.uint8, 4),
    "bgra8": (np.uint8, 4),
    "mono8": (np.uint8, 1),
    "mono16": (np.uint16, 1),
    "16UC1": (np.uint16, 1),
    "32FC1": (np.float32, 1),
    "8UC1": (np.uint8, 1),
    "8UC3": (np.uint8, 3),
    "rgb16": (np.uint16, 3),
    "16SC1": (np.int16, 1),
    "64FC1": (np.float64, 1),
}

# Generated rclpy message modules whose field checks we switch on in the strict test.
RCLPY_MODULES = [
    "builtin_interfaces.msg._time",
    "std_msgs.msg._header",
    "sensor_msgs.msg._image",
    "sensor_msgs.msg._compressed_image",
    "sensor_msgs.msg._camera_info",
    "sensor_msgs.msg._region_of_interest",
    "sensor_msgs.msg._point_cloud2",
    "sensor_msgs.msg._point_field",
    "sensor_msgs.msg._joint_state",
]


@pytest.fixture(scope="module")
def rosbags_factory():
    return mf.default_factory()


@pytest.fixture(params=["rosbags", "rclpy"])
def factory(request):
    return mf.default_factory() if request.param == "rosbags" else mf.RclpyFactory()


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


def random_image(rng, dtype, channels, height=7, width=5):
    shape = (height, width) if channels == 1 else (height, width, channels)
    if np.dtype(dtype).kind == "f":
        return rng.normal(2.0, 1.5, shape).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(info.min, info.max, shape, dtype=dtype, endpoint=True)


def raw_image(factory, encoding, height, width, step, data, is_bigendian=0):
    """Build an Image with hand-made fields (to create padded/big-endian/malformed ones)."""
    return factory.make(
        "sensor_msgs/msg/Image",
        height=height,
        width=width,
        encoding=encoding,
        step=step,
        is_bigendian=is_bigendian,
        data=np.frombuffer(bytes(data), dtype=np.uint8),
    )


# ---------------------------------------------------------------------------------------------
# msg_factory
# ---------------------------------------------------------------------------------------------


def test_typename_of_both_flavours(factory):
    msg = factory.make("sensor_msgs/msg/Image")
    assert mf.typename_of(msg) == "sensor_msgs/msg/Image"
    assert mf.typename_of(type(msg)) == "sensor_msgs/msg/Image"
    assert mf.typename_of(factory.make("std_msgs/Header")) == "std_msgs/msg/Header"
    with pytest.raises(mf.MessageFactoryError, match="not a ROS message"):
        mf.typename_of(object())


@pytest.mark.parametrize("ns", [0, 1, 999_999_999, 1_700_000_000_123_456_789, -1, -1_500_000_000])
def test_stamp_round_trip(factory, ns):
    stamp = mf.ns_to_stamp(ns, factory)
    assert 0 <= stamp.nanosec < 1_000_000_000
    assert mf.stamp_to_ns(stamp) == ns
    header = mf.make_header(factory, ns, "cam0")
    assert header.frame_id == "cam0"
    assert mf.stamp_to_ns(header) == ns


def test_factory_rejects_unknown_type_and_field(factory):
    with pytest.raises(mf.MessageFactoryError, match="NoSuchMsg"):
        factory.make("sensor_msgs/msg/NoSuchMsg")
    with pytest.raises(mf.MessageFactoryError, match="no field.*'colour'"):
        factory.make("sensor_msgs/msg/Image", colour=3)
    with pytest.raises(mf.MessageFactoryError, match="fixed array of 9 elements, got 4"):
        factory.make("sensor_msgs/msg/CameraInfo", k=np.zeros(4))


def test_factory_defaults_and_coercion(factory):
    info = factory.make("sensor_msgs/msg/CameraInfo", width=np.int64(640), d=[0.1, 0.2])
    assert info.width == 640 and type(info.width) is int
    assert info.height == 0 and info.distortion_model == ""
    np.testing.assert_array_equal(np.asarray(info.k), np.zeros(9))
    np.testing.assert_array_equal(np.asarray(info.d), [0.1, 0.2])
    assert info.roi.do_rectify is False


def test_rosbags_factory_makes_serialisable_messages(rosbags_factory, rng):
    ts = rosbags_factory.typestore
    image = conv.numpy_to_image(random_image(rng, np.uint16, 1), "16UC1", 42, "depth")
    raw = ts.serialize_cdr(image, "sensor_msgs/msg/Image")
    back = ts.deserialize_cdr(raw, "sensor_msgs/msg/Image")
    np.testing.assert_array_equal(conv.image_to_numpy(back), conv.image_to_numpy(image))
    assert mf.stamp_to_ns(back.header.stamp) == 42


def test_rclpy_image_serialises_identically(rng, rosbags_factory):
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Image

    array = random_image(rng, np.uint8, 3, 48, 64)
    rclpy_msg = conv.numpy_to_image(array, "rgb8", 1_234_567_890_123, "cam", mf.RclpyFactory())
    wire = serialize_message(rclpy_msg)
    back = deserialize_message(wire, Image)
    assert back == rclpy_msg
    np.testing.assert_array_equal(conv.image_to_numpy(back), array)
    # The same image built as a rosbags dataclass is interchangeable on the wire (equal length;
    # CDR alignment padding bytes are unspecified, so compare after cross-deserialising).
    ts = rosbags_factory.typestore
    rosbags_msg = conv.numpy_to_image(array, "rgb8", 1_234_567_890_123, "cam")
    rosbags_wire = bytes(ts.serialize_cdr(rosbags_msg, "sensor_msgs/msg/Image"))
    assert len(rosbags_wire) == len(wire)
    assert deserialize_message(rosbags_wire, Image) == rclpy_msg
    from_rclpy = ts.deserialize_cdr(wire, "sensor_msgs/msg/Image")
    assert (from_rclpy.encoding, from_rclpy.step) == ("rgb8", 64 * 3)
    np.testing.assert_array_equal(conv.image_to_numpy(from_rclpy), array)


def test_rclpy_factory_passes_strict_field_checks(monkeypatch, rng):
    """With ROS_PYTHON_CHECK_FIELDS=1 the generated setters assert types; ours must pass."""
    for name in RCLPY_MODULES:
        monkeypatch.setattr(importlib.import_module(name), "ros_python_check_fields", "1")
    factory = mf.RclpyFactory()
    image = conv.numpy_to_image(random_image(rng, np.uint8, 3, 480, 640), "rgb8", factory=factory)
    assert image._check_fields and len(image.data) == 480 * 640 * 3
    conv.numpy_to_compressed(random_image(rng, np.uint8, 1), "png", factory=factory)
    conv.dict_to_camera_info({"width": 4, "height": 3, "K": np.eye(3)}, factory=factory)
    conv.xyz_to_pointcloud2(rng.normal(size=(10, 3)), 5, "map", factory)
    conv.make_joint_state(["a", "b"], np.array([1.0, 2.0]), factory=factory)


# ---------------------------------------------------------------------------------------------
# Image
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("encoding", sorted(ENCODINGS))
def test_image_round_trip(factory, rng, encoding):
    dtype, channels = ENCODINGS[encoding]
    array = random_image(rng, dtype, channels)
    msg = conv.numpy_to_image(
        array, encoding, stamp_ns=3_000_000_007, frame_id="cam1", factory=factory
    )
    assert msg.encoding == encoding and msg.is_bigendian == 0
    assert (msg.height, msg.width) == (7, 5)
    assert msg.step == 5 * channels * np.dtype(dtype).itemsize
    assert len(msg.data) == msg.step * msg.height
    assert mf.stamp_to_ns(msg.header.stamp) == 3_000_000_007 and msg.header.frame_id == "cam1"
    back = conv.image_to_numpy(msg)
    assert back.dtype == np.dtype(dtype) and back.shape == array.shape
    np.testing.assert_array_equal(back, array)


def test_image_to_numpy_returns_independent_copy(factory, rng):
    array = random_image(rng, np.uint8, 3)
    msg = conv.numpy_to_image(array, "rgb8", factory=factory)
    array[:] = 0  # the message must not alias the input either
    back = conv.image_to_numpy(msg)
    assert back.flags.writeable and back.flags.c_contiguous and back.any()
    back[:] = 0
    assert conv.image_to_numpy(msg).any()


def test_image_accepts_hxwx1_for_mono(rng):
    array = random_image(rng, np.uint8, 1)
    msg = conv.numpy_to_image(array[:, :, None], "mono8")
    np.testing.assert_array_equal(conv.image_to_numpy(msg), array)


def test_padded_step(factory, rng):
    array = random_image(rng, np.uint8, 3, 6, 4)
    step = 4 * 3 + 5
    rows = np.full((6, step), 0xAB, dtype=np.uint8)
    rows[:, : 4 * 3] = array.reshape(6, -1)
    msg = raw_image(factory, "rgb8", 6, 4, step, rows.tobytes())
    np.testing.assert_array_equal(conv.image_to_numpy(msg), array)


@pytest.mark.parametrize(
    ("encoding", "dtype"), [("mono16", ">u2"), ("16UC1", ">u2"), ("32FC1", ">f4")]
)
def test_big_endian_images(factory, rng, encoding, dtype):
    native = random_image(rng, np.dtype(dtype).newbyteorder("="), 1, 5, 6)
    itemsize = np.dtype(dtype).itemsize
    step = 6 * itemsize + 3  # padded as well
    rows = np.zeros((5, step), dtype=np.uint8)
    wire = np.frombuffer(native.astype(dtype).tobytes(), np.uint8)
    rows[:, : 6 * itemsize] = wire.reshape(5, -1)
    msg = raw_image(factory, encoding, 5, 6, step, rows.tobytes(), is_bigendian=1)
    back = conv.image_to_numpy(msg)
    assert back.dtype.isnative
    np.testing.assert_array_equal(back, native)
    # Read as little-endian the same bytes give different values: is_bigendian really matters.
    msg.is_bigendian = 0
    assert not np.array_equal(conv.image_to_numpy(msg), native)


def test_numpy_to_image_writes_little_endian_from_big_endian_input(rng):
    native = random_image(rng, np.uint16, 1)
    msg = conv.numpy_to_image(native.astype(">u2"), "16UC1")
    assert msg.is_bigendian == 0
    assert bytes(msg.data) == native.astype("<u2").tobytes()


@pytest.mark.parametrize(
    ("fields", "pattern"),
    [
        ({"encoding": "yuv422_yuy2"}, "unsupported image encoding 'yuv422_yuy2'"),
        ({"step": 11}, r"step 11 < width 4 x 3 bytes per pixel = 12"),
        ({"data": bytes(12 * 3 - 1)}, r"data has 35 bytes, expected step 12 x height 3 = 36"),
        ({"height": 0}, "zero size"),
        ({"width": 0, "step": 0}, "zero size"),
    ],
)
def test_malformed_images_raise(factory, fields, pattern):
    args = {"encoding": "rgb8", "height": 3, "width": 4, "step": 12, "data": bytes(36)}
    args.update(fields)
    msg = raw_image(factory, **args)
    with pytest.raises(conv.ImageConversionError, match=pattern):
        conv.image_to_numpy(msg)
    # ImageConversionError is a ConversionError is a ValueError: nodes can catch either.
    with pytest.raises(conv.ConversionError):
        conv.image_to_numpy(msg)
    with pytest.raises(ValueError):
        conv.image_to_numpy(msg)


@pytest.mark.parametrize(
    ("array", "encoding", "pattern"),
    [
        (np.zeros((3, 4, 3), np.float32), "rgb8", "needs a uint8 array, got float32"),
        (np.zeros((3, 4), np.uint8), "rgb8", r"needs an HxWx3 array, got shape \(3, 4\)"),
        (np.zeros((3, 4), np.int32), "16UC1", "needs a uint16 array, got int32"),
        (np.zeros((3, 4, 3), np.uint8), "mono8", "needs an HxW or HxWx1"),
        (np.zeros((0, 4), np.uint8), "mono8", "empty image"),
        (np.zeros((3, 4), np.uint8), "bayer_rggb8", "unsupported image encoding"),
    ],
)
def test_numpy_to_image_rejects_bad_arrays(array, encoding, pattern):
    with pytest.raises(conv.ImageConversionError, match=pattern):
        conv.numpy_to_image(array, encoding)


def test_image_to_rgb(factory, rng):
    rgb = random_image(rng, np.uint8, 3)
    alpha = random_image(rng, np.uint8, 1)[:, :, None]
    cases = {
        "rgb8": rgb,
        "bgr8": rgb[:, :, ::-1],
        "rgba8": np.concatenate([rgb, alpha], axis=2),
        "bgra8": np.concatenate([rgb[:, :, ::-1], alpha], axis=2),
    }
    for encoding, array in cases.items():
        out = conv.image_to_rgb(conv.numpy_to_image(array, encoding, factory=factory))
        assert out.shape == rgb.shape and out.dtype == np.uint8, encoding
        np.testing.assert_array_equal(out, rgb, err_msg=encoding)
    mono = rgb[:, :, 0]
    out = conv.image_to_rgb(conv.numpy_to_image(mono, "mono8", factory=factory))
    np.testing.assert_array_equal(out, np.stack([mono] * 3, axis=2))
    mono16 = mono.astype(np.uint16) * 256 + 17
    out = conv.image_to_rgb(conv.numpy_to_image(mono16, "mono16", factory=factory))
    np.testing.assert_array_equal(out[:, :, 1], mono)
    with pytest.raises(conv.ImageConversionError, match="depth_image_to_metres"):
        conv.image_to_rgb(conv.numpy_to_image(np.ones((2, 2), np.float32), "32FC1"))


def test_depth_image_to_metres(factory):
    mm = np.array([[0, 1000, 2500], [65535, 1, 0]], dtype=np.uint16)
    depth = conv.depth_image_to_metres(conv.numpy_to_image(mm, "16UC1", factory=factory))
    assert depth.dtype == np.float32
    expected = np.array([[np.nan, 1.0, 2.5], [65.535, 0.001, np.nan]], dtype=np.float32)
    np.testing.assert_allclose(depth, expected, rtol=1e-6)
    custom = conv.depth_image_to_metres(
        conv.numpy_to_image(mm, "16UC1"), depth_unit=0.0001, invalid_value=65535
    )
    np.testing.assert_allclose(custom, [[0.0, 0.1, 0.25], [np.nan, 0.0001, 0.0]], rtol=1e-6)

    metres = np.array([[0.0, 1.25, np.nan], [np.inf, -np.inf, 3.0]], dtype=np.float32)
    depth = conv.depth_image_to_metres(conv.numpy_to_image(metres, "32FC1", factory=factory))
    np.testing.assert_array_equal(depth, [[np.nan, 1.25, np.nan], [np.nan, np.nan, 3.0]])
    with pytest.raises(conv.ImageConversionError, match="16UC1, mono16 or 32FC1"):
        conv.depth_image_to_metres(conv.numpy_to_image(np.zeros((2, 2, 3), np.uint8), "rgb8"))


# ---------------------------------------------------------------------------------------------
# CompressedImage
# ---------------------------------------------------------------------------------------------


def smooth_rgb(height=48, width=64):
    y, x = np.mgrid[0:height, 0:width]
    channels = [x * 255 // width, y * 255 // height, (x + y) * 2 % 256]
    return np.stack(channels, axis=2).astype(np.uint8)


def test_jpeg_round_trip_is_close_and_rgb_ordered(factory):
    rgb = smooth_rgb()
    rgb[:16, :16] = (255, 0, 0)  # a red block must stay red (RGB/BGR order)
    msg = conv.numpy_to_compressed(rgb, "jpeg", 77, "cam", factory, quality=95)
    assert msg.format == "rgb8; jpeg compressed bgr8"
    assert mf.stamp_to_ns(msg.header.stamp) == 77 and msg.header.frame_id == "cam"
    assert bytes(msg.data[:2]) == b"\xff\xd8"
    back = conv.compressed_to_numpy(msg)
    assert back.shape == rgb.shape and back.dtype == np.uint8
    assert np.abs(back.astype(int) - rgb).mean() < 3.0
    red = back[4:12, 4:12].reshape(-1, 3).mean(axis=0)
    assert red[0] > 230 and red[1] < 25 and red[2] < 25


@pytest.mark.parametrize(
    ("array", "fmt_string"),
    [
        (smooth_rgb(), "rgb8; png compressed bgr8"),
        (smooth_rgb()[:, :, 0], "mono8; png compressed mono8"),
        (np.arange(48 * 64, dtype=np.uint16).reshape(48, 64) * 13, "16UC1; png compressed"),
        (np.dstack([smooth_rgb(), smooth_rgb()[:, :, :1]]), "rgba8; png compressed bgra8"),
    ],
)
def test_png_round_trip_is_exact(factory, array, fmt_string):
    msg = conv.numpy_to_compressed(array, "png", factory=factory)
    assert msg.format == fmt_string
    back = conv.compressed_to_numpy(msg)
    assert back.dtype == array.dtype
    np.testing.assert_array_equal(back, array)


def test_compressed_bare_format_strings_decode(rosbags_factory):
    rgb = smooth_rgb()
    _, png = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    msg = rosbags_factory.make(
        "sensor_msgs/msg/CompressedImage", format="png", data=png.reshape(-1)
    )
    np.testing.assert_array_equal(conv.compressed_to_numpy(msg), rgb)


@pytest.mark.parametrize(
    ("fmt", "data", "pattern"),
    [
        ("jpeg", b"\xff\xd8\xff\xe0garbage" * 10, "could not be decoded"),
        ("png", bytes(range(200)), "could not be decoded"),
        ("jpeg", b"", "has no data"),
        ("rgb8; theora", b"\x00" * 10, "unsupported compressed image format"),
        ("16UC1; compressedDepth png", b"\x00" * 40, "no PNG payload"),
    ],
)
def test_corrupt_compressed_data_raises(factory, fmt, data, pattern):
    msg = factory.make(
        "sensor_msgs/msg/CompressedImage", format=fmt, data=np.frombuffer(data, np.uint8)
    )
    with pytest.raises(conv.CompressedImageError, match=pattern):
        conv.compressed_to_numpy(msg)


def test_truncated_jpeg_raises():
    msg = conv.numpy_to_compressed(smooth_rgb(), "jpeg")
    msg.data = msg.data[:20]
    with pytest.raises(conv.ConversionError, match="could not be decoded"):
        conv.compressed_to_numpy(msg)


def test_numpy_to_compressed_rejects_bad_input():
    with pytest.raises(conv.CompressedImageError, match="'jpeg' or 'png'"):
        conv.numpy_to_compressed(smooth_rgb(), "webp")
    with pytest.raises(conv.CompressedImageError, match="cannot jpeg-compress a uint16"):
        conv.numpy_to_compressed(np.zeros((4, 4), np.uint16), "jpeg")
    with pytest.raises(conv.CompressedImageError, match="float32"):
        conv.numpy_to_compressed(np.zeros((4, 4, 3), np.float32), "png")


def test_compressed_depth_png(rosbags_factory):
    mm = (np.arange(30 * 20, dtype=np.uint16).reshape(30, 20) * 7) % 9000
    _, png = cv2.imencode(".png", mm)
    header = struct.pack("<iff", 0, 0.0, 0.0)
    msg = rosbags_factory.make(
        "sensor_msgs/msg/CompressedImage",
        format="16UC1; compressedDepth png",
        data=np.frombuffer(header + png.tobytes(), np.uint8),
    )
    np.testing.assert_array_equal(conv.compressed_to_numpy(msg), mm)

    # 32FC1: compressed_depth_image_transport stores q = A / depth + B (0 = no depth).
    quant_a, quant_b = 100.0, 10.0
    depth = np.array([[0.5, 1.0], [2.0, np.nan]], dtype=np.float32)
    q = np.where(np.isfinite(depth), quant_a / depth + quant_b, 0).astype(np.uint16)
    _, png = cv2.imencode(".png", q)
    msg = rosbags_factory.make(
        "sensor_msgs/msg/CompressedImage",
        format="32FC1; compressedDepth png",
        data=np.frombuffer(struct.pack("<iff", 0, quant_a, quant_b) + png.tobytes(), np.uint8),
    )
    np.testing.assert_allclose(conv.compressed_to_numpy(msg), depth, rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# CameraInfo
# ---------------------------------------------------------------------------------------------


def camera_dict():
    k = np.array([[525.0, 0.0, 319.5], [0.0, 526.0, 239.5], [0.0, 0.0, 1.0]])
    return {
        "width": 640,
        "height": 480,
        "K": k,
        "D": np.array([0.1, -0.2, 0.001, 0.002, 0.05]),
        "distortion_model": "plumb_bob",
        "R": np.eye(3),
        "P": np.hstack([k, [[0.0], [0.0], [0.0]]]),
        "frame_id": "cam0_optical",
    }


def test_camera_info_round_trip(factory):
    d = camera_dict()
    msg = conv.dict_to_camera_info(d, stamp_ns=123, factory=factory)
    assert msg.width == 640 and msg.height == 480 and msg.distortion_model == "plumb_bob"
    assert mf.stamp_to_ns(msg.header.stamp) == 123
    np.testing.assert_array_equal(np.asarray(msg.k), d["K"].reshape(-1))
    back = conv.camera_info_to_dict(msg)
    assert tuple(back) == conv.CAMERA_INFO_KEYS
    assert set(back) == {"width", "height", "K", "D", "distortion_model", "R", "P", "frame_id"}
    for key in ("K", "D", "R", "P"):
        assert back[key].dtype == np.float64
        np.testing.assert_array_equal(back[key], d[key], err_msg=key)
    assert back["K"].shape == (3, 3) and back["R"].shape == (3, 3) and back["P"].shape == (3, 4)
    assert (back["width"], back["height"], back["frame_id"]) == (640, 480, "cam0_optical")


def test_camera_info_defaults():
    d = {"width": 4, "height": 3, "K": [2.0, 0, 1.5, 0, 2.0, 1.0, 0, 0, 1]}
    back = conv.camera_info_to_dict(conv.dict_to_camera_info(d))
    np.testing.assert_array_equal(back["R"], np.eye(3))
    np.testing.assert_array_equal(back["P"][:, :3], back["K"])
    np.testing.assert_array_equal(back["P"][:, 3], 0.0)
    assert back["D"].shape == (0,) and back["distortion_model"] == "plumb_bob"


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        ({"K": np.zeros(8)}, r"K must have 9 numbers \(3x3\), got 8"),
        ({"P": np.zeros((3, 3))}, r"P must have 12 numbers"),
        ({"R": [[1, 0], [0, 1]]}, r"R must have 9 numbers"),
        ({"D": [0.1, np.nan]}, "D has non-finite"),
        ({"K": "abc"}, "K is not numeric"),
        ({"width": 0}, "width must be a positive integer"),
        ({"height": 2.5}, "height must be a positive integer"),
        ({"fx": 500.0}, r"unknown key\(s\) \['fx'\]"),
    ],
)
def test_dict_to_camera_info_validates(change, pattern):
    d = camera_dict()
    d.update(change)
    with pytest.raises(conv.CameraInfoConversionError, match=pattern):
        conv.dict_to_camera_info(d)


def test_dict_to_camera_info_requires_keys():
    with pytest.raises(conv.CameraInfoConversionError, match=r"lacks required key\(s\) \['K'\]"):
        conv.dict_to_camera_info({"width": 4, "height": 3})


def test_camera_info_to_dict_validates_message():
    msg = conv.dict_to_camera_info(camera_dict())
    msg.k = np.zeros(8)
    with pytest.raises(conv.CameraInfoConversionError, match="k must have 9 numbers"):
        conv.camera_info_to_dict(msg)


# ---------------------------------------------------------------------------------------------
# PointCloud2
# ---------------------------------------------------------------------------------------------

PADDED_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "intensity", "ring", "normal", "t"],
        "formats": ["<f4", "<f4", "<f4", "u1", "<u2", ("<f4", (3,)), "<f8"],
        "offsets": [0, 4, 8, 16, 18, 20, 40],
        "itemsize": 48,
    }
)


def padded_cloud(rng, shape):
    points = np.zeros(shape, dtype=PADDED_DTYPE)
    for axis in "xyz":
        points[axis] = rng.normal(size=shape)
    points["intensity"] = rng.integers(0, 255, shape)
    points["ring"] = rng.integers(0, 65535, shape)
    points["normal"] = rng.normal(size=shape + (3,))
    points["t"] = rng.normal(size=shape) * 1e6
    return points


def assert_clouds_equal(actual, expected):
    assert actual.dtype.names == expected.dtype.names
    for name in expected.dtype.names:
        np.testing.assert_array_equal(actual[name], expected[name], err_msg=name)


def test_pointcloud2_round_trip_with_padding(factory, rng):
    points = padded_cloud(rng, (50,))
    msg = conv.array_to_pointcloud2(points, 99, "lidar", factory)
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 50, 48, 48 * 50)
    assert msg.is_bigendian is False or msg.is_bigendian == 0
    assert bool(msg.is_dense) is True
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, 7, 1),
        ("y", 4, 7, 1),
        ("z", 8, 7, 1),
        ("intensity", 16, 2, 1),
        ("ring", 18, 4, 1),
        ("normal", 20, 7, 3),
        ("t", 40, 8, 1),
    ]
    assert len(msg.data) == 48 * 50
    back = conv.pointcloud2_to_array(msg)
    assert back.shape == (50,) and back.dtype.itemsize == 48
    assert_clouds_equal(back, points)
    np.testing.assert_array_equal(back["normal"], points["normal"])


def test_organized_pointcloud_with_row_padding(factory, rng):
    points = padded_cloud(rng, (3, 4))
    points["x"][1, 2] = np.nan
    msg = conv.array_to_pointcloud2(points, factory=factory)
    assert (msg.height, msg.width) == (3, 4) and not msg.is_dense
    # Re-pack with 7 padding bytes per row to exercise row_step.
    rows = np.frombuffer(bytes(msg.data), np.uint8).reshape(3, 4 * 48)
    padded = np.hstack([rows, np.full((3, 7), 0xEE, np.uint8)])
    msg = factory.make(
        "sensor_msgs/msg/PointCloud2",
        height=3,
        width=4,
        fields=msg.fields,
        point_step=48,
        row_step=4 * 48 + 7,
        data=padded.reshape(-1),
    )
    back = conv.pointcloud2_to_array(msg, organized=True)
    assert back.shape == (3, 4)
    assert_clouds_equal(back, points)
    assert conv.pointcloud2_to_array(msg).shape == (12,)


def test_big_endian_pointcloud(factory, rng):
    points = padded_cloud(rng, (20,))
    big = points.astype(PADDED_DTYPE.newbyteorder(">"))
    reference = conv.array_to_pointcloud2(points, factory=factory)
    msg = factory.make(
        "sensor_msgs/msg/PointCloud2",
        height=1,
        width=20,
        fields=reference.fields,
        is_bigendian=True,
        point_step=48,
        row_step=48 * 20,
        data=np.frombuffer(big.tobytes(), np.uint8),
    )
    back = conv.pointcloud2_to_array(msg)
    assert all(back.dtype.fields[name][0].base.isnative for name in back.dtype.names)
    assert_clouds_equal(back, points)
    msg.is_bigendian = False  # the flag is honoured, not ignored
    assert not np.array_equal(conv.pointcloud2_to_array(msg)["x"], points["x"])


def test_array_to_pointcloud2_writes_little_endian_from_big_endian_array(rng):
    points = padded_cloud(rng, (5,))
    msg = conv.array_to_pointcloud2(points.astype(PADDED_DTYPE.newbyteorder(">")))
    assert not msg.is_bigendian
    assert bytes(msg.data) == points.tobytes()
    assert_clouds_equal(conv.pointcloud2_to_array(msg), points)


def test_xyz_round_trip(factory, rng):
    xyz = rng.normal(size=(100, 3))
    msg = conv.xyz_to_pointcloud2(xyz, 5, "map", factory)
    assert msg.point_step == 12 and [f.name for f in msg.fields] == ["x", "y", "z"]
    assert msg.header.frame_id == "map"
    np.testing.assert_array_equal(conv.pointcloud2_to_xyz(msg), xyz.astype(np.float32))
    xyz[3] = np.nan
    msg = conv.xyz_to_pointcloud2(xyz, factory=factory)
    assert not msg.is_dense
    assert conv.pointcloud2_to_xyz(msg, skip_nans=True).shape == (99, 3)
    with pytest.raises(conv.PointCloudConversionError, match="Nx3"):
        conv.xyz_to_pointcloud2(np.zeros((4, 2)))


def test_empty_pointcloud(factory):
    msg = conv.xyz_to_pointcloud2(np.zeros((0, 3)), factory=factory)
    assert conv.pointcloud2_to_array(msg).shape == (0,)


def point_field(factory, name, offset, datatype, count=1):
    return factory.make(
        "sensor_msgs/msg/PointField", name=name, offset=offset, datatype=datatype, count=count
    )


@pytest.mark.parametrize(
    ("fields", "data_size", "pattern"),
    [
        ([("x", 0, 9)], 80, "unknown datatype 9"),
        ([("x", 0, 7), ("y", 2, 7)], 80, "'x' and 'y' overlap"),
        ([("x", 0, 7), ("x", 4, 7)], 80, "empty or repeated"),
        ([("x", 6, 8)], 80, "does not fit point_step 8"),
        ([("x", 0, 7)], 79, "data has 79 bytes, expected at least 80"),
    ],
)
def test_malformed_pointcloud_raises(factory, fields, data_size, pattern):
    msg = factory.make(
        "sensor_msgs/msg/PointCloud2",
        height=1,
        width=10,
        fields=[point_field(factory, *f) for f in fields],
        point_step=8,
        row_step=80,
        data=np.zeros(data_size, np.uint8),
    )
    with pytest.raises(conv.PointCloudConversionError, match=pattern):
        conv.pointcloud2_to_array(msg)


def test_array_to_pointcloud2_rejects_unsupported(rng):
    with pytest.raises(conv.PointCloudConversionError, match="structured array"):
        conv.array_to_pointcloud2(np.zeros((4, 3), np.float32))
    with pytest.raises(conv.PointCloudConversionError, match="'stamp'.*cannot express"):
        conv.array_to_pointcloud2(np.zeros(4, dtype=[("x", "f4"), ("stamp", "i8")]))


# ---------------------------------------------------------------------------------------------
# JointState
# ---------------------------------------------------------------------------------------------


def test_joint_state_round_trip(factory):
    names = ["hip", "knee", "ankle"]
    msg = conv.make_joint_state(
        names, np.array([0.1, -0.5, 1.25]), 1_000_000_001, "pelvis",
        velocity=[1.0, 2.0, 3.0], factory=factory,
    )
    d = conv.joint_state_to_dict(msg)
    assert d["name"] == names and d["stamp_ns"] == 1_000_000_001 and d["frame_id"] == "pelvis"
    np.testing.assert_array_equal(d["position"], [0.1, -0.5, 1.25])
    np.testing.assert_array_equal(d["velocity"], [1.0, 2.0, 3.0])
    assert d["effort"].shape == (0,) and d["position"].dtype == np.float64


def test_joint_state_validates_lengths(factory):
    with pytest.raises(conv.JointStateConversionError, match="position has 2 values for 3"):
        conv.make_joint_state(["a", "b", "c"], [1.0, 2.0], factory=factory)
    with pytest.raises(conv.JointStateConversionError, match="repeat"):
        conv.make_joint_state(["a", "a"], [1.0, 2.0])
    msg = factory.make("sensor_msgs/msg/JointState", name=["a", "b"], effort=[1.0])
    with pytest.raises(conv.JointStateConversionError, match="effort has 1 values for 2"):
        conv.joint_state_to_dict(msg)
