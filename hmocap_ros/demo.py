"""``hmocap demo``: the shipped recording through real nodes over DDS, recorded and checked.

Stage of the pipeline so far: the shipped 4-camera bag is replayed (``hmocap replay``) into
``camera_rig_publisher``, which publishes the rig (latched) and a CameraInfo for every image;
``hmocap record`` writes what comes out to ``<out>/demo_out.mcap``. Each runs in its own
process over DDS on loopback. The demo then reads both bags and reports, per camera, the
frames that went in, the CameraInfo messages that came out, and whether their stamps match.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import loopback_dds_env, replay_through_nodes

DATA_DIR = Path(__file__).resolve().parent / "data" / "demo"
DEMO_BAG = DATA_DIR / "mocap_4cam.mcap"
DEMO_RIG = DATA_DIR / "mocap_4cam_rig.yaml"


def _image_topics(bag: Path) -> list[str]:
    with BagReader(bag) as reader:
        return sorted(t for t, info in reader.topics().items() if t.endswith("/image_raw")
                      and info.msgtype == "sensor_msgs/msg/Image")


def _stamps(bag: Path, topics: list[str]) -> dict[str, list[int]]:
    out = {t: [] for t in topics}
    with BagReader(bag) as reader:
        present = [t for t in topics if t in reader.topics()]
        for m in reader.messages(present):
            out[m.topic].append(stamp_to_ns(m.msg.header.stamp))
    return out


def run_demo(out: str | Path = "out/demo", domain_id: int | None = None, bag: Path = DEMO_BAG,
             rig: Path = DEMO_RIG) -> int:
    """Run the demo; return 0 when every input frame produced its output with the same stamp."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    out_bag = out / "demo_out.mcap"
    if out_bag.exists():
        out_bag.unlink()
    shutil.rmtree(out / "logs", ignore_errors=True)
    env = loopback_dds_env(domain_id=domain_id)
    image_topics = _image_topics(bag)
    cameras = [t.strip("/").split("/")[0] for t in image_topics]
    info_topics = [f"/{c}/camera_info" for c in cameras]
    print(f"demo: input {bag.name}: {len(cameras)} cameras ({', '.join(cameras)})")
    print(f"demo: DDS domain {env.get('ROS_DOMAIN_ID', '0')}, discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE']}")

    t0 = time.monotonic()
    logs = out / "logs"
    replay_through_nodes(
        bag,
        [("camera_rig_publisher", "hmocap_ros.nodes.camera_rig_publisher",
          ["--ros-args", "-p", f"rig_file:={rig}"], "serving rig")],
        ["/camera_rig", *info_topics], out_bag, env, logs, replay_topics=image_topics)
    elapsed = time.monotonic() - t0
    print("demo: replay -> camera_rig_publisher -> record, logs in", logs)

    sent = _stamps(bag, image_topics)
    got = _stamps(out_bag, info_topics)
    ok = True
    for cam, img_t, info_t in zip(cameras, image_topics, info_topics, strict=True):
        match = sorted(got[info_t]) == sorted(sent[img_t])
        ok &= match
        print(f"  {cam}: {len(sent[img_t])} images in -> {len(got[info_t])} camera_info out, "
              f"stamps {'identical' if match else 'DIFFER'}")
    with BagReader(out_bag) as reader:
        rig_msg = reader.first("/camera_rig")
    if rig_msg is None:
        ok = False
        print("  camera_rig: MISSING")
    else:
        print(f"  camera_rig: {len(rig_msg.camera_names)} cameras, frame '{rig_msg.header.frame_id}'")
    print(f"demo: {'OK' if ok else 'FAILED'} in {elapsed:.1f} s; output bag {out_bag}")
    return 0 if ok else 1
