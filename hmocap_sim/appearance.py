"""What the simulated person wears: skin, hair and clothes on the body mesh.

Every vertex of the body model gets a label from its body part (``BodyModel.vertex_part``, the
dominant skinning joint) and its position in the rest pose (model frame: metres, +Y up,
facing +Z): skin on face, neck and hands (and forearms with short sleeves), hair on the
scalp, a shirt on the torso and arms, trousers from the waist down, shoes on the feet. A face
takes the material of the majority of its vertices; colours are per vertex, so a boundary
(a sleeve, the waist) is a one-triangle blend instead of a zigzag along mesh edges.

Skin tones are measured-like sRGB values from very light to dark (all inside the usual
skin-colour clusters, e.g. Cr 135-175 / Cb 85-125 in YCbCr, so a real skin detector finds the
face and hands); clothes avoid skin-like hues so that hands stay distinguishable. A few smooth
per-vertex tints (eye sockets, brows, lips, cheeks, a darker sole) add facial detail without
changing the labels.

    look = dress(model, sample_appearance(rng))
    # look.face_material indexes PERSON_MATERIALS; look.vertex_colours (V, 3) (sRGB) multiply
    # the material colours; look.face_colours (F, 3) are ones (kept for renderers' use).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_sim.render.meshes import vertex_normals
from hmocap_sim.render.shading import Material

__all__ = ["SKIN", "HAIR", "SHIRT", "TROUSERS", "SHOES", "LABEL_NAMES", "SKIN_TONES",
           "PersonAppearance", "PersonLook", "PERSON_MATERIALS", "sample_appearance",
           "label_weights", "vertex_labels", "dress"]

SKIN, HAIR, SHIRT, TROUSERS, SHOES = range(5)
HAIR_THICKNESS = 0.012  # metres of hair volume over the scalp
LABEL_NAMES = ("skin", "hair", "shirt", "trousers", "shoes")

#: Skin tones (sRGB, 0-1) from very light to dark.
SKIN_TONES = (
    (0.95, 0.80, 0.70), (0.91, 0.74, 0.62), (0.85, 0.66, 0.53), (0.78, 0.58, 0.44),
    (0.69, 0.50, 0.36), (0.56, 0.39, 0.27), (0.43, 0.29, 0.20),
)
HAIR_COLOURS = ((0.07, 0.06, 0.05), (0.16, 0.10, 0.07), (0.26, 0.17, 0.10), (0.10, 0.08, 0.07),
                (0.45, 0.33, 0.20), (0.55, 0.54, 0.52), (0.20, 0.13, 0.09), (0.62, 0.48, 0.30))
SHIRT_COLOURS = ((0.13, 0.33, 0.62), (0.08, 0.12, 0.28), (0.62, 0.12, 0.14), (0.14, 0.42, 0.26),
                 (0.55, 0.56, 0.58), (0.90, 0.90, 0.88), (0.12, 0.12, 0.13), (0.08, 0.45, 0.48),
                 (0.40, 0.22, 0.50), (0.80, 0.68, 0.15), (0.30, 0.55, 0.75))
TROUSER_COLOURS = ((0.12, 0.15, 0.24), (0.18, 0.25, 0.40), (0.08, 0.08, 0.09), (0.32, 0.32, 0.34),
                   (0.25, 0.28, 0.18), (0.10, 0.12, 0.18))
SHOE_COLOURS = ((0.06, 0.06, 0.06), (0.85, 0.85, 0.83), (0.30, 0.18, 0.10), (0.20, 0.20, 0.24))

#: Materials of a person, indexed by label; colours come from face and vertex colours.
PERSON_MATERIALS = (
    Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, smooth=True, specular=0.06,
             noise=0.03, scale=0.01),                                                  # skin
    Material("fabric", (1.0, 1.0, 1.0), scale=0.01, noise=0.18, vertex_colour=True,
             smooth=True, specular=0.12, seed=21),                                     # hair
    Material("fabric", (1.0, 1.0, 1.0), scale=0.07, noise=0.22, vertex_colour=True,
             smooth=True, seed=22),                                                    # shirt
    Material("fabric", (1.0, 1.0, 1.0), scale=0.06, noise=0.25, vertex_colour=True,
             smooth=True, seed=23),                                                    # trousers
    Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, smooth=True, specular=0.25,
             noise=0.05, scale=0.02),                                                  # shoes
)


@dataclass(frozen=True)
class PersonAppearance:
    """Colours (sRGB, 0-1) and cut of one person's look."""

    skin: tuple = SKIN_TONES[2]
    hair: tuple = HAIR_COLOURS[1]
    shirt: tuple = SHIRT_COLOURS[0]
    trousers: tuple = TROUSER_COLOURS[0]
    shoes: tuple = SHOE_COLOURS[0]
    long_sleeves: bool = False
    long_hair: bool = False

    def colour(self, label: int) -> tuple:
        return (self.skin, self.hair, self.shirt, self.trousers, self.shoes)[label]


def sample_appearance(rng: np.random.Generator) -> PersonAppearance:
    """A random look: skin tone, hair, shirt, trousers, shoes, sleeve and hair length."""

    def pick(options):
        base = np.asarray(options[int(rng.integers(len(options)))], float)
        return tuple(np.clip(base * rng.uniform(0.92, 1.08, 3), 0.0, 1.0).round(4))

    return PersonAppearance(
        skin=pick(SKIN_TONES), hair=pick(HAIR_COLOURS), shirt=pick(SHIRT_COLOURS),
        trousers=pick(TROUSER_COLOURS), shoes=pick(SHOE_COLOURS),
        long_sleeves=bool(rng.random() < 0.4), long_hair=bool(rng.random() < 0.3))


@dataclass(frozen=True, eq=False)
class PersonLook:
    """Per-face material and colours of a dressed body mesh (arrays read-only)."""

    appearance: PersonAppearance
    vertex_label: np.ndarray  # (V,) int
    face_label: np.ndarray  # (F,) int, index into PERSON_MATERIALS
    face_colours: np.ndarray  # (F, 3) float32 sRGB multipliers (ones)
    vertex_colours: np.ndarray  # (V, 3) float32 sRGB: label colour times facial detail
    hair_offset: np.ndarray  # (V,) float32 metres: hair volume along the vertex normal

    def with_hair(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """Posed ``vertices (V, 3)`` with the hair's volume added along the normals (the
        mesh stays closed: only vertex positions change)."""
        v = np.asarray(vertices, np.float32)
        if not self.hair_offset.any():
            return v
        return v + self.hair_offset[:, None] * vertex_normals(v, faces)

    @property
    def face_material(self) -> np.ndarray:
        return self.face_label


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def label_weights(model, appearance: PersonAppearance) -> np.ndarray:
    """Soft label weights ``(V, 5)`` (rows sum to 1) of the rest vertices of ``model``.

    Body parts decide most labels; the cuts that cross parts (waist, sleeves, collar, shoe
    tops, hairline) are smooth functions of the rest position, so that interpolated colours
    draw a straight line instead of following the mesh's zigzag.
    """
    names = model.joint_names
    part_name = np.array(names, dtype=object)[np.asarray(model.vertex_part)]
    v = np.asarray(model.vertices, float)
    joint = {n: np.asarray(model.joints_rest[i], float) for i, n in enumerate(names)}
    w = np.zeros((len(v), len(LABEL_NAMES)))

    def is_part(*prefixes):
        return np.array([str(p).startswith(prefixes) for p in part_name])

    def assign(mask, label, amount=1.0):
        """Move ``amount`` (per vertex, 0-1) of the weight of ``mask`` vertices to ``label``."""
        amount = np.broadcast_to(np.asarray(amount, float), (len(v),)) * mask
        w[:] *= (1.0 - amount)[:, None]
        w[:, label] += amount

    y = v[:, 1]
    # Torso and arms: shirt; hands: skin; legs: trousers; head and neck: skin.
    assign(np.ones(len(v), bool), SHIRT)
    hands = is_part("l_wrist", "r_wrist", "l_thumb", "r_thumb", "l_index", "r_index",
                    "l_middle", "r_middle", "l_ring", "r_ring", "l_pinky", "r_pinky")
    legs = is_part("l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle", "l_toe", "r_toe")
    head = is_part("head")
    neck = is_part("neck")
    # Waist: trousers below a level line a little above the pelvis joint (legs included: the
    # thighs' skinning region reaches above the waist at the sides).
    waist = joint["pelvis"][1] + 0.045
    assign(legs | is_part("pelvis", "spine"), TROUSERS,
           1.0 - _smoothstep(waist - 0.008, waist + 0.008, y))
    # Sleeves: short ones end 45 % down the upper arm, long ones just above the wrist.
    for s in ("l", "r"):
        a, b, c = joint[f"{s}_shoulder"], joint[f"{s}_elbow"], joint[f"{s}_wrist"]
        t_up = (v - a) @ (b - a) / np.dot(b - a, b - a)
        t_fore = (v - b) @ (c - b) / np.dot(c - b, c - b)
        arm = is_part(f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist")
        if appearance.long_sleeves:
            assign(arm, SKIN, _smoothstep(0.90, 0.96, t_fore) * (t_up > 1.0))
        else:
            assign(arm, SKIN, np.maximum(_smoothstep(0.42, 0.48, t_up), (t_fore > 0.0) * 1.0))
    assign(hands, SKIN)
    # Collar: skin above a line around the neck's base, lower at the front.
    nk = joint["neck"]
    front_n = _smoothstep(0.0, 0.09, v[:, 2] - nk[2])
    collar = nk[1] - 0.03 - 0.035 * front_n
    assign(neck | is_part("chest", "l_clavicle", "r_clavicle"), SKIN,
           _smoothstep(collar - 0.006, collar + 0.006, y))
    assign(head, SKIN)
    # Shoes: everything on the legs below a level just above the ankles.
    ankle_y = 0.5 * (joint["l_ankle"][1] + joint["r_ankle"][1])
    assign(legs, SHOES, 1.0 - _smoothstep(ankle_y + 0.025, ankle_y + 0.04, y))
    # Hair: above a hairline that is low at the back of the skull and high on the forehead.
    hy = joint["head"][1]
    centre_z = 0.5 * (v[head, 2].min() + v[head, 2].max()) if head.any() else 0.0
    zz = v[:, 2] - centre_z
    front = _smoothstep(-0.01, 0.08, zz)
    back_line = -0.12 if appearance.long_hair else -0.035
    hairline = hy + back_line + (0.088 - back_line) * front
    hair_w = _smoothstep(hairline - 0.005, hairline + 0.005, y)
    assign(head, HAIR, hair_w)
    if appearance.long_hair:
        assign(neck, HAIR, _smoothstep(-0.01, -0.03, zz) * (y > hy - 0.16))
    return w


def vertex_labels(model, appearance: PersonAppearance) -> np.ndarray:
    """Label (SKIN, HAIR, SHIRT, TROUSERS, SHOES) of every rest vertex of ``model``."""
    return np.argmax(label_weights(model, appearance), axis=1)


def _face_labels(faces: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per face, the label with the largest mean weight over its three vertices."""
    return np.argmax(weights[faces].mean(axis=1), axis=1)


def _facial_tints(model, vertex_label) -> np.ndarray:
    """Smooth multipliers on the face: shadowed eye sockets with dark irises, brows, reddish
    lips and cheeks (Gaussian blobs around points placed relative to the nose tip)."""
    v = np.asarray(model.vertices, float)
    names = model.joint_names
    head = np.asarray(model.vertex_part) == names.index("head")
    tint = np.ones((len(v), 3))
    if not head.any():
        return tint.astype(np.float32)
    nose = v[head][np.argmax(v[head, 2])]

    def blob(centre, sigma, colour, strength):
        d2 = ((v - centre) ** 2).sum(1)
        w = strength * np.exp(-0.5 * d2 / sigma ** 2) * head
        tint[:] = tint * (1.0 - w[:, None]) + np.asarray(colour) * w[:, None]

    for sx in (-1.0, 1.0):
        # The mesh has open eye sockets (no eyeballs): their back reads as the eye.
        eye = nose + [sx * 0.033, 0.037, -0.058]
        blob(eye, 0.022, (0.62, 0.55, 0.52), 0.6)  # lids and socket shade
        blob(eye, 0.015, (0.2, 0.16, 0.15), 0.9)  # iris, pupil, lashes, socket walls
        blob(nose + [sx * 0.034, 0.058, -0.022], 0.008, (0.45, 0.38, 0.34), 0.7)  # brow
        blob(nose + [sx * 0.045, 0.0, -0.03], 0.018, (1.05, 0.88, 0.86), 0.5)  # cheek
    blob(nose + [0.0, -0.036, -0.018], 0.009, (0.88, 0.62, 0.6), 0.85)  # lips
    tint[vertex_label != SKIN] = 1.0
    return np.clip(tint, 0.0, 1.2).astype(np.float32)


def dress(model, appearance: PersonAppearance) -> PersonLook:
    """Labels, per-face materials and colours of ``model`` (any body asset) for a look."""
    weights = label_weights(model, appearance)
    labels = np.argmax(weights, axis=1)
    faces = np.asarray(model.faces)
    face_label = _face_labels(faces, weights)
    palette = np.array([appearance.colour(k) for k in range(len(LABEL_NAMES))], np.float32)
    face_colours = np.ones((len(faces), 3), np.float32)
    vertex_colours = (weights @ palette).astype(np.float32) * _facial_tints(model, labels)
    # Darker soles and a slightly darker waistband, still inside their labels.
    v = np.asarray(model.vertices)
    vertex_colours[(labels == SHOES) & (v[:, 1] < 0.012)] *= 0.55
    pelvis_y = model.joints_rest[model.joint_names.index("pelvis")][1]
    band = (labels == TROUSERS) & (v[:, 1] > pelvis_y + 0.005)
    vertex_colours[band] *= 0.75
    hair = (weights[:, HAIR] * HAIR_THICKNESS).astype(np.float32)
    out = PersonLook(appearance, labels, face_label.astype(np.int32),
                     np.ascontiguousarray(face_colours), np.ascontiguousarray(vertex_colours),
                     hair)
    for a in (out.vertex_label, out.face_label, out.face_colours, out.vertex_colours,
              out.hair_offset):
        a.flags.writeable = False
    return out
