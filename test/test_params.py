"""``hmocap_ros.param_overrides``: KEY=VALUE strings typed as a parameter dataclass' fields."""
import pytest

from hmocap_ros.eval.mocap_eval import tracker_overrides
from hmocap_ros.params import field_overrides
from hmocap_ros.segmentation import ForegroundParams


def test_values_are_typed_as_the_fields_defaults():
    out = field_overrides(ForegroundParams, ["k_sigma=3", "learn_frames=7", "shadow_suppression=no",
                                             "illumination_compensation=On"])
    assert out == {"k_sigma": 3.0, "learn_frames": 7, "shadow_suppression": False,
                   "illumination_compensation": True}
    assert type(out["k_sigma"]) is float and type(out["learn_frames"]) is int
    assert tracker_overrides(["track_region=-1, 0,2.5,3"]) == {"track_region": [-1.0, 0.0, 2.5, 3.0]}
    assert field_overrides(ForegroundParams, None) == {}


def test_bad_items_name_what_is_wrong():
    with pytest.raises(ValueError, match="expected KEY=VALUE"):
        field_overrides(ForegroundParams, ["k_sigma"])
    with pytest.raises(ValueError, match="unknown tracker parameter 'nope'"):
        tracker_overrides(["nope=1"])
    with pytest.raises(ValueError):
        field_overrides(ForegroundParams, ["learn_frames=many"])
