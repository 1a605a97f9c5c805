"""``hmocap sim mocap``: a multi-view RGB recording of a retargeted BVH clip, with ground truth.

A seeded, deterministic synthetic smart-room recording (shared/DESIGN.md, sec. 5): a subject
whose body shape is drawn from the anthropometric priors (:func:`hmocap_ros.body.sample_shape`)
performs a real CMU motion-capture clip (retargeted onto the body,
:mod:`hmocap_sim.retarget`) in a furnished room (:mod:`hmocap_sim.room`) seen by N
calibrated colour cameras at 25 fps; :mod:`hmocap_sim.mocap_render` renders every view with
its exact ground-truth silhouette.
The same seed gives the same bytes in every image; a different seed gives another subject,
look, room variation, placement and noise.

Output, next to each other (``BAG`` = ``--out``, e.g. ``run.mcap``):

- ``BAG``: an MCAP bag in the documented layout (:mod:`hmocap_ros.io.topics`):
  ``/camera_rig`` (latched ``hmocap_interfaces/CameraRig``), ``/cam_k/image_raw`` (rgb8),
  ``/ground_truth/cam_k/silhouette`` (mono8 0/255: pixels whose nearest surface is the
  subject), ``/ground_truth/skeleton`` (``hmocap_interfaces/Skeleton``: the 19 body joints,
  then the 5 end sites head_top, l/r_hand_tip, l/r_toe, with parents, in metres in the room
  frame), ``/ground_truth/joint_states`` (``sensor_msgs/JointState``: the tracking body
  model's 30 DoFs, ``hmocap_ros.body.load_body_model("tracking")``; posing that model with
  them and the body shape reproduces the skeleton exactly), ``/ground_truth/body_shape``
  (latched ``hmocap_interfaces/BodyShape``). Every message of a frame has the same
  ``header.stamp`` and is logged at it; room-frame data has frame id ``room``, images the
  camera's optical frame id.
- ``<stem>_rig.yaml``: the rig (``hmocap_ros.geometry.rig.load_rig`` format).
- ``<stem>.contact.png``: a contact sheet (all views of a few frames, every person's
  ground-truth skeleton projected, the subject's silhouette outlined).

The recording starts with ``--background-seconds`` of the empty room (for background
models to learn; those frames have images and empty silhouettes but no skeleton or joint
states), then the subject appears and performs ``--seconds`` of the clip from ``--start``.
With ``--background-seconds 0`` the subject is in view from the first frame, as in most real
recordings; ``--still-seconds`` makes the subject first stand still in the clip's first pose
for that long (someone waiting for the recording to start: no pixel of the body's outline
changes then, so no background model can tell the person from the room by motion).
The subject is placed (position and heading searched with the seed) so that all joints stay
inside every camera's image and away from the furniture; a motion that travels farther than
the cameras' common view (a run) is placed to stay in view as long as it can, with a warning.
``--people N`` adds persons 1..N-1 with ground truth (:mod:`~hmocap_sim.mocap_people`), each
with a clip, a body and a look of their own: their skeleton, joint states, body shape and
silhouettes are on the subject's topics under ``/ground_truth/body_<k>/``, with body id
``body_<k>`` (:func:`hmocap_ros.eval.people_truth.person_topic`).
``--distractors`` adds a door that opens and closes, a ball rolling across the floor and a
second person at the side of the room, which all cause foreground that is not the subject (and
may occlude it: the silhouettes stay exact). ``--lighting-changes`` adds sudden lighting
events during the motion (on top of the small drifts of daylight and exposure every recording
has): the ceiling lamp dims to about a third and comes back, the cameras' auto-exposure follows
with a lag, and a cloud darkens the window light for a second.

The rendered mesh is the finer ``hands`` body (12,000 triangles, relaxed fingers, hair volume)
posed with the same parameters as the tracking body, so joints coincide exactly and the
silhouettes are those of the finer surface.

The parts: :mod:`~hmocap_sim.mocap_rig` (cameras), :mod:`~hmocap_sim.mocap_subject`
(random streams, subject, placement), :mod:`~hmocap_sim.mocap_people`,
:mod:`~hmocap_sim.mocap_distractors`,
:mod:`~hmocap_sim.mocap_lighting`, :mod:`~hmocap_sim.mocap_frames` (the frame loop) and
:mod:`~hmocap_sim.mocap_outputs` (the files beside the bag); this module sets a recording up
from its options and runs them.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hmocap_sim.mocap_distractors import DistractorContext, build_distractors
from hmocap_sim.mocap_frames import Timeline, write_frames, write_latched
from hmocap_sim.mocap_lighting import camera_gains, light_levels
from hmocap_sim.mocap_outputs import (
    clear_outputs,
    output_paths,
    save_contact_sheet,
    save_rig_yaml,
)
from hmocap_sim.mocap_people import MAX_PEOPLE, build_people, people_stream
from hmocap_sim.mocap_rig import make_rig, views_seeing
from hmocap_sim.mocap_subject import make_performer, random_streams, subject_in_room
from hmocap_sim.params import DEFAULT_BVH, MocapSimConfig

__all__ = ["MocapSimConfig", "SimResult", "make_rig", "generate", "views_seeing", "DEFAULT_BVH",
           "BASE_STAMP_NS"]

BASE_STAMP_NS = 1_700_000_000_000_000_000

@dataclass(frozen=True, eq=False)
class SimResult:
    """What :func:`generate` wrote and how long it took."""

    bag: Path
    rig_yaml: Path
    contact_sheet: Path
    n_frames: int
    n_motion_frames: int
    n_cameras: int
    width: int
    height: int
    bag_bytes: int
    render_seconds_per_frame: float
    total_seconds: float
    stamps_ns: tuple = field(default=())
    timings: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- recording


@dataclass(frozen=True, eq=False)
class _Recording:
    """A recording set up and ready to render: what :func:`generate` writes."""

    rig: object
    tracking: object
    full: object
    performers: list  # the people with ground truth (the subject first), then the distractors'
    n_people: int  # people with ground truth
    renderer: object
    timeline: Timeline
    n_motion: int


def _set_up(config: MocapSimConfig) -> _Recording:
    """Draw everything of a recording from its seed's streams (``mocap_subject.random_streams``)."""
    from hmocap_ros.body import load_body_model
    from hmocap_sim.appearance import dress, sample_appearance
    from hmocap_sim.mocap_render import MocapRenderer, RenderOptions

    fps = float(config.fps)
    (rng_room, rng_shape, rng_look, rng_place, rng_dist, rng_light, rng_cam,
     rng_events) = random_streams(config.seed)
    rig, room, tracking, shape, motion = subject_in_room(config, rng_room, rng_shape,
                                                          rng_place)
    full = load_body_model("hands", "full")
    look = dress(full, sample_appearance(rng_look))
    subject = make_performer(motion, tracking, full, shape, look)
    people = build_people(config.people, subject=subject, subject_bvh=Path(config.bvh), rig=rig,
                          room=room, tracking=tracking, full=full, fps=fps,
                          rng=people_stream(config.seed))
    n_motion = len(subject.params)
    n_bg = int(round(config.background_seconds * fps))
    n_frames = n_bg + n_motion
    t = np.arange(n_frames) / fps
    t_motion, t_end = n_bg / fps, n_frames / fps
    distractors = build_distractors(
        DistractorContext(t=t, t_motion=t_motion, t_end=t_end, fps=fps, rig=rig, room=room,
                          tracking=tracking, full=full, subject=subject,
                          people=tuple(people)),
        rng_dist, config.distractors)
    window_gain, exposure, lamp_gain = light_levels(rng_light, rng_events, t, t_motion, t_end,
                                                    config.lighting_changes)
    gains = camera_gains(rng_cam, len(rig))
    performers = [subject, *people, *distractors.performers]
    options = RenderOptions(shadows=config.shadows, noise=config.noise,
                            supersample=config.supersample)
    renderer = MocapRenderer(rig, room, [(full.faces, p.look) for p in performers], options,
                             camera_gains=gains, with_ball=distractors.with_ball,
                             truth_people=1 + len(people))
    stamps = BASE_STAMP_NS + np.round(np.arange(n_frames) * 1e9 / fps).astype(np.int64)
    timeline = Timeline(stamps=stamps, n_background=n_bg, door=distractors.door,
                        balls=distractors.balls, window_gain=window_gain, exposure=exposure,
                        lamp_gain=lamp_gain)
    return _Recording(rig, tracking, full, performers, 1 + len(people), renderer, timeline,
                      n_motion)


def _sheet_frames(n_background: int, n_motion: int, n_sheet: int) -> set:
    """Frames of the contact sheet: ``n_sheet`` spread over 10-90 % of the motion."""
    if not n_sheet:
        return set()
    return set((n_background + np.linspace(0.1, 0.9, n_sheet) * (n_motion - 1)).round()
               .astype(int).tolist())


def _sheet_title(config: MocapSimConfig, rig) -> str:
    return (f"{Path(config.bvh).name} from {config.start:g} s, seed {config.seed}, "
            f"{len(rig)} cameras {rig[0].width}x{rig[0].height}"
            + (f", {config.people} people" if config.people > 1 else "")
            + (", distractors" if config.distractors else "")
            + (", lighting changes" if config.lighting_changes else ""))


def generate(config: MocapSimConfig) -> SimResult:
    """Render and write one recording (module docstring); returns what was written."""
    import numba
    from tqdm import tqdm

    from hmocap_ros.io.bag_writer import whole_bag
    from hmocap_ros.io.msg_factory import RosbagsFactory
    from hmocap_ros.io.typestore import hmocap_typestore

    t_start = time.perf_counter()
    if not 1 <= int(config.people) <= MAX_PEOPLE:
        raise ValueError(f"--people must be between 1 and {MAX_PEOPLE}, got {config.people}")
    out = Path(config.out)
    rig_path, sheet_path = output_paths(out)
    clear_outputs((out, rig_path, sheet_path), config.force)
    bvh = Path(config.bvh)
    if not bvh.is_file():
        raise FileNotFoundError(f"BVH file {bvh} not found")
    rec = _set_up(config)
    rig, timeline = rec.rig, rec.timeline
    n_frames = len(timeline.stamps)
    n_bg = timeline.n_background
    factory = RosbagsFactory(hmocap_typestore())
    with whole_bag(out) as bag:
        write_latched(bag, factory, rig, rec.tracking, rec.performers[:rec.n_people],
                      int(timeline.stamps[0]))
        bar = tqdm(total=n_frames, desc=f"rendering {out.name}", unit="frame", file=sys.stderr,
                   disable=not config.progress, dynamic_ncols=True)
        loop = write_frames(bag, factory, rec.renderer, rec.tracking, rec.full, rec.performers,
                            rec.n_people, timeline, config.seed,
                            _sheet_frames(n_bg, rec.n_motion, max(0, int(config.contact_frames))),
                            bar)
        bar.close()

    save_rig_yaml(rig, rig_path, out.name, config.seed)
    save_contact_sheet(sheet_path, loop.sheet_rows, n_bg, float(config.fps),
                       _sheet_title(config, rig))
    result = SimResult(
        bag=out, rig_yaml=rig_path, contact_sheet=sheet_path, n_frames=n_frames,
        n_motion_frames=rec.n_motion, n_cameras=len(rig), width=rig[0].width,
        height=rig[0].height, bag_bytes=out.stat().st_size,
        render_seconds_per_frame=loop.render_seconds / max(n_frames, 1),
        total_seconds=time.perf_counter() - t_start,
        stamps_ns=tuple(int(s) for s in timeline.stamps),
        timings={k: v / max(n_frames, 1) for k, v in loop.stage_seconds.items()})
    result.timings["threads"] = numba.get_num_threads()
    return result
