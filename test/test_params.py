"""``hmocap_ros.params``: described fields, groups by dotted name, KEY=VALUE overrides."""
from dataclasses import dataclass

import pytest

from hmocap_ros.eval.mocap_eval import tracker_overrides
from hmocap_ros.params import field_overrides, flat_fields, flat_record, from_flat, group, param, replace_dotted
from hmocap_ros.segmentation import ForegroundParams
from hmocap_ros.tracking.params import StartupParams, TrackerParams


@dataclass(frozen=True)
class _Inner:
    size: float = param(0.5, "a size (m)")
    names: list[str] = param([], "names")


@dataclass(frozen=True)
class _Outer:
    count: int = param(3, "a count")
    inner: _Inner = group(_Inner, "the inner group")


def test_groups_flatten_to_dotted_names_and_back():
    assert [name for name, *_ in flat_fields(_Outer)] == ["count", "inner.size", "inner.names"]
    built = from_flat(_Outer, {"inner.size": 2.0})
    assert built == _Outer(count=3, inner=_Inner(size=2.0))
    assert flat_record(built) == {"count": 3, "inner.size": 2.0, "inner.names": []}
    assert from_flat(_Outer, flat_record(built)) == built
    assert replace_dotted(built, {"count": 5}).inner.size == 2.0
    with pytest.raises(ValueError, match="inner.nope"):
        from_flat(_Outer, {"inner.nope": 1})
    with pytest.raises(ValueError, match="unknown"):
        replace_dotted(built, {"size": 1.0})


def test_values_are_typed_as_the_fields_defaults():
    out = field_overrides(ForegroundParams, ["k_sigma=3", "learn_frames=7", "shadow_suppression=no",
                                             "illumination_compensation=On"])
    assert out == {"k_sigma": 3.0, "learn_frames": 7, "shadow_suppression": False,
                   "illumination_compensation": True}
    assert type(out["k_sigma"]) is float and type(out["learn_frames"]) is int
    region = tracker_overrides(["startup.track_region=-1, 0,2.5,3", "filter.sweeps=1"])
    assert region == {"startup.track_region": [-1.0, 0.0, 2.5, 3.0], "filter.sweeps": 1}
    params = from_flat(TrackerParams, region)
    assert params.startup.track_region == (-1.0, 0.0, 2.5, 3.0)
    assert params.filter.sweeps == 1 and params.startup == replace_dotted(
        StartupParams(), {"track_region": [-1.0, 0.0, 2.5, 3.0]})
    assert field_overrides(ForegroundParams, None) == {}


def test_bad_items_name_what_is_wrong():
    with pytest.raises(ValueError, match="expected KEY=VALUE"):
        field_overrides(ForegroundParams, ["k_sigma"])
    with pytest.raises(ValueError, match="unknown tracker parameter 'nope'"):
        tracker_overrides(["nope=1"])
    with pytest.raises(ValueError, match="unknown tracker parameter 'sweeps'"):
        tracker_overrides(["sweeps=1"])  # a leaf of a group is named with its group
    with pytest.raises(ValueError):
        field_overrides(ForegroundParams, ["learn_frames=many"])
    with pytest.raises(ValueError, match="filter.sweeps must be >= 1"):
        from_flat(TrackerParams, {"filter.sweeps": 0})
