"""The other people of a simulated recording with ground truth (``--people N``).

Besides the subject (person 0), persons 1..N-1 each perform a CMU clip of their own (from
:data:`PEOPLE_BVH`, never the subject's clip, chosen with the seed, clips played in place
before walks) with a body shape and a
look of their own, over the same frames as the subject. Each is placed like the subject
(:func:`~hmocap_sim.mocap_subject.place_subject`: inside every camera's view and off the
furniture, if a candidate can), and also :data:`~hmocap_sim.mocap_subject.PERSON_GAP` from
the people placed before at every instant where it can; their paths may still cross in front
of a camera, so one person may occlude another. All of it draws from one random stream of its
own (:func:`people_stream`), so the subject, the room and the distractors are those of the
same seed with ``--people 1``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from hmocap_sim.mocap_subject import (
    make_performer,
    place_subject,
    retargeted_motion,
    shaped_skeleton,
)
from hmocap_sim.params import DATA_DIR

__all__ = ["MAX_PEOPLE", "PEOPLE_BVH", "build_people", "people_stream", "person_clips",
           "pingpong_frames"]

#: ``--people``: at most this many people with ground truth, the subject included
MAX_PEOPLE = 4

#: The clips persons 1.. perform, in two groups: those played in place (wave, laugh, crouch and
#: throw), then the walks, which cross the room and may leave a view (not the 1.2 s run)
PEOPLE_BVH = (tuple(DATA_DIR / "bvh" / name for name in
                    ("13_26.bvh", "14_19_first1201.bvh", "002_06_first511.bvh")),
              tuple(DATA_DIR / "bvh" / name for name in ("002_01.bvh", "007_01.bvh")))


def people_stream(seed: int) -> np.random.Generator:
    """The random stream of persons 1..N-1: the ninth child of the seed's sequence, beside the
    eight of :func:`~hmocap_sim.mocap_subject.random_streams`."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(8,)))


def person_clips(subject_bvh: Path, n: int, rng: np.random.Generator) -> list[Path]:
    """``n`` different clips of :data:`PEOPLE_BVH` other than the subject's: the clips played in
    place first, then the walks, each group in an order drawn from ``rng``."""
    subject = Path(subject_bvh).name
    pool = []
    for group in PEOPLE_BVH:
        clips = [p for p in group if p.name != subject]
        pool += [clips[int(i)] for i in rng.permutation(len(clips))]
    if n > len(pool):
        raise ValueError(f"--people {n + 1}: only {len(pool)} clips besides the subject's")
    return pool[:n]


def pingpong_frames(n_clip: int, n: int, first: int = 0) -> np.ndarray:
    """``n`` frame indices of a clip of ``n_clip`` frames from ``first``, running back and
    forth through it when it ends (a clip shorter than the recording)."""
    if n_clip < 2:
        return np.zeros(n, dtype=np.intp)
    period = 2 * n_clip - 2
    idx = (first + np.arange(n)) % period
    return np.where(idx < n_clip, idx, period - idx)


def build_people(n: int, *, subject, subject_bvh: Path, rig, room, tracking, full, fps: float,
                 rng: np.random.Generator) -> list:
    """Performers of persons 1..n-1 (module docstring), as many frames as the subject's."""
    from hmocap_ros.body import sample_shape
    from hmocap_sim.appearance import dress, sample_appearance

    if n <= 1:
        return []
    n_motion = len(subject.params)
    tracks = [subject.joints[:, 0][:, [0, 2]]]
    people = []
    for k, clip in enumerate(person_clips(subject_bvh, n - 1, rng), start=1):
        shape = sample_shape(rng)
        look = dress(full, sample_appearance(rng))
        motion = retargeted_motion(clip, tracking, shape, fps)
        # from 0.2 s in: the first frames of some clips are a T-pose blending into the motion
        lo = min(int(round(0.2 * fps)), motion.n_frames - 1)
        first = int(rng.integers(lo, max(lo + 1, motion.n_frames - n_motion)))
        idx = pingpong_frames(motion.n_frames, n_motion, first)
        motion = replace(motion, local_rotations=motion.local_rotations[idx],
                         root_translation=motion.root_translation[idx], source_frames=None)
        motion = place_subject(motion, rig, room, rng, shaped_skeleton(tracking, shape),
                               avoid=tracks, who=f"person {k} ({clip.name})")
        person = make_performer(motion, tracking, full, shape, look)
        people.append(person)
        tracks.append(person.joints[:, 0][:, [0, 2]])
    return people
