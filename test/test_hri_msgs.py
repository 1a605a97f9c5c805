"""REP-155's ``hri_msgs/msg/IdsList``: the type of ``humans/bodies/tracked`` is the released one.

The environment's hri_msgs (a ROS install's, or ``msg_defs_hri/`` built by ``make setup``) must
have the type hash of ROS 2 Jazzy's hri_msgs 2.3.2, so that ROS4HRI tools (pyhri, libhri, RViz's
humans plugin) subscribe to our topic, and a bag written offline (rosbags) must store the same
type. The hash is computed twice, independently: by rosidl when the package was built (its
``share/hri_msgs/msg/IdsList.json``) and by rosbags from the released definition below.
"""
from __future__ import annotations

import json
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

#: The fields of ``msg/IdsList.msg`` in hri_msgs 2.3.2 (ROS 2 Jazzy's release, ros4hri/hri_msgs).
RELEASED_IDS_LIST = "std_msgs/Header header\nstring[] ids\n"
#: Its RIHS01 type hash (rosidl's and rosbags' computation agree on it).
RELEASED_IDS_LIST_HASH = "RIHS01_7e0812d1ac945c98fd3e393568d581ad0ab567f37b24eff633eab778c1bfe62d"
#: RIHS01 type hash of tf2_msgs/msg/TFMessage in ROS 2 Jazzy (`ros2 topic info -v /tf`): checks
#: the hasher on a type whose released hash is known from a ROS install.
JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def test_rosbags_hashes_the_released_definition():
    store = get_typestore(Stores.ROS2_JAZZY)
    assert store.hash_rihs01("tf2_msgs/msg/TFMessage") == JAZZY_TFMESSAGE_HASH
    store.register(get_types_from_msg(RELEASED_IDS_LIST, "hri_msgs/msg/IdsList"))
    assert store.hash_rihs01("hri_msgs/msg/IdsList") == RELEASED_IDS_LIST_HASH


def test_environment_hri_msgs_has_the_released_type_hash():
    import hri_msgs
    from hri_msgs.msg import IdsList

    assert IdsList.get_fields_and_field_types() == {"header": "std_msgs/Header", "ids": "sequence<string>"}
    share = [Path(p).parents[3] / "share" / "hri_msgs" / "msg" / "IdsList.json" for p in hri_msgs.__path__]
    found = [p for p in share if p.is_file()]
    assert found, f"no type description next to hri_msgs ({share}): the package was not built"
    description = json.loads(found[0].read_text())
    assert description["type_hashes"][0] == {"type_name": "hri_msgs/msg/IdsList",
                                             "hash_string": RELEASED_IDS_LIST_HASH}


def test_bags_store_the_released_ids_list():
    """What ``hmocap track`` and the recorder's factory write into a bag."""
    from hmocap_ros.io.typestore import hmocap_typestore
    from hmocap_ros.tracking.tracker_messages import IDS_LIST_TYPE, TRACKED_TOPIC, tracker_topics

    assert tracker_topics(["b0"])[TRACKED_TOPIC] == IDS_LIST_TYPE == "hri_msgs/msg/IdsList"
    assert hmocap_typestore().hash_rihs01(IDS_LIST_TYPE) == RELEASED_IDS_LIST_HASH


def test_msg_defs_hri_is_the_released_definition():
    text = (Path(__file__).resolve().parents[1] / "msg_defs_hri" / "msg" / "IdsList.msg").read_text()
    fields = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    assert "\n".join(fields) + "\n" == RELEASED_IDS_LIST
