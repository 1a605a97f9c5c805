"""Bag writing and reading: round trips, latched topics, single file vs directory, mcap-ros2 readers."""

import numpy as np
import pytest

from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.bag_writer import LATCHED, BagWriteError, BagWriter, whole_bag
from hmocap_ros.io.conversions import image_to_numpy, numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header, stamp_to_ns
from hmocap_ros.io.typestore import hmocap_typestore


def _gesture_array(factory, stamp_ns):
    gesture = factory.make(
        "hmocap_interfaces/msg/Gesture", name="tee", class_id=1, score=0.75, volume=0.5, u=10.0, v=20.0,
        position=factory.make("geometry_msgs/msg/Point", x=0.1, y=0.2, z=2.0), position_valid=True)
    return factory.make("hmocap_interfaces/msg/GestureArray", header=make_header(factory, stamp_ns, "depth"),
                        gestures=[gesture])


def _write_sample(path, n=5):
    factory = RosbagsFactory(hmocap_typestore())
    images = []
    with BagWriter(path) as bag:
        rig = factory.make("std_msgs/msg/String", data="rig")
        bag.add_topic("/camera_rig_text", "std_msgs/msg/String", LATCHED)
        bag.write("/camera_rig_text", rig, 1_000)
        for i in range(n):
            stamp = 1_000_000_000 + i * 40_000_000
            img = np.full((6, 8, 3), i, np.uint8)
            images.append(img)
            for cam in ("cam_1", "cam_2"):
                bag.write(f"/{cam}/image_raw", numpy_to_image(img, "rgb8", stamp, cam, factory), stamp)
            bag.write("/gestures", _gesture_array(factory, stamp), stamp)
    return images


@pytest.mark.parametrize("name", ["run.mcap", "run_dir"])
def test_round_trip(tmp_path, name):
    path = tmp_path / name
    images = _write_sample(path)
    assert path.is_file() == name.endswith(".mcap")
    with BagReader(path) as reader:
        topics = reader.topics()
        assert topics["/cam_1/image_raw"].count == 5
        assert topics["/camera_rig_text"].latched and not topics["/gestures"].latched
        got = [image_to_numpy(m.msg) for m in reader.messages(["/cam_2/image_raw"])]
        assert all(np.array_equal(a, b) for a, b in zip(got, images, strict=True))
        times = [m.log_time_ns for m in reader.messages()]
        assert times == sorted(times)
        g = reader.first("/gestures").gestures[0]
        assert (g.name, g.class_id, g.position.z, g.position_valid) == ("tee", 1, 2.0, True)


def test_frame_sets_exact(tmp_path):
    path = tmp_path / "sets.mcap"
    _write_sample(path, n=4)
    with BagReader(path) as reader:
        sets = list(reader.frame_sets(["/cam_1/image_raw", "/cam_2/image_raw"]))
    assert [s for s, _ in sets] == [1_000_000_000 + i * 40_000_000 for i in range(4)]
    for stamp, frames in sets:
        assert {stamp_to_ns(m.header.stamp) for m in frames.values()} == {stamp}


def test_mcap_ros2_support_reads_our_bag(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = tmp_path / "x.mcap"
    _write_sample(path, n=3)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = [m for _, _, _, m in reader.iter_decoded_messages(topics=["/gestures"])]
    assert len(msgs) == 3
    assert msgs[0].gestures[0].name == "tee"
    assert msgs[1].header.stamp.nanosec == 40_000_000


def test_errors(tmp_path):
    path = tmp_path / "a.mcap"
    _write_sample(path, n=1)
    with pytest.raises(BagWriteError, match="exists"):
        BagWriter(path)
    with pytest.raises(BagReadError, match="does not exist"):
        BagReader(tmp_path / "missing.mcap")
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(BagReadError):
        with BagReader(corrupt) as reader:
            list(reader.messages())
    with BagReader(path) as reader:
        with pytest.raises(BagReadError, match="no topic"):
            list(reader.messages(["/nope"]))


@pytest.mark.parametrize("name", ["gen.mcap", "gen_dir"])
def test_whole_bag_is_complete_or_absent(tmp_path, name):
    path = tmp_path / name
    factory = RosbagsFactory(hmocap_typestore())
    msg = factory.make("std_msgs/msg/String", data="frame")
    with pytest.raises(KeyboardInterrupt):
        with whole_bag(path) as bag:
            bag.write("/text", msg, 1_000)
            raise KeyboardInterrupt  # Ctrl-C half-way through a generated data set
    assert not path.exists() and sorted(p.name for p in tmp_path.iterdir()) == []
    with whole_bag(path) as bag:  # the same path then writes normally
        bag.write("/text", msg, 1_000)
    with BagReader(path) as reader:
        assert [m.msg.data for m in reader.messages()] == ["frame"]


def test_generated_bags_do_not_depend_on_the_wall_clock(tmp_path, monkeypatch):
    """A generated bag's bytes are a function of its messages: ``whole_bag`` closes chunks by
    size only. A writer that flushed on a timer would cut chunks wherever the clock (a loaded
    machine) made it, and the same data set would come out in other bytes."""
    import hmocap_ros.io.bag_writer as bag_writer

    factory = RosbagsFactory(hmocap_typestore())
    msgs = [factory.make("std_msgs/msg/String", data=f"frame {i}") for i in range(20)]

    def write(path, seconds_per_message):
        clock = iter(np.arange(1000) * seconds_per_message)
        monkeypatch.setattr(bag_writer.time, "monotonic", lambda: float(next(clock)))
        with whole_bag(path) as bag:
            for i, msg in enumerate(msgs):
                bag.write("/text", msg, 1_000 + i)
        return path.read_bytes()

    (tmp_path / "idle").mkdir()
    (tmp_path / "loaded").mkdir()
    assert write(tmp_path / "idle" / "g.mcap", 0.0) == write(tmp_path / "loaded" / "g.mcap", 5.0)
    # a recorder keeps its timed flush (what a killed recorder loses is bounded by it)
    clock = iter(np.arange(1000) * 5.0)
    monkeypatch.setattr(bag_writer.time, "monotonic", lambda: float(next(clock)))
    with BagWriter(tmp_path / "recorded.mcap") as bag:
        bag.write("/text", msgs[0], 1_000)
        assert bag._unflushed == 0
