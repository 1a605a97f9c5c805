"""Pieces the furnished room is assembled from, built in place into a
:class:`~hmocap_sim.room_mesh.MeshBuilder`: a wall with openings, a framed picture, a
chair and a bookshelf filled with random books."""

from __future__ import annotations

import numpy as np

from hmocap_sim.room_mesh import MeshBuilder, box_mesh, cells_along, textured_quad

_BOOK_COLOURS = [(0.55, 0.12, 0.10), (0.12, 0.22, 0.45), (0.15, 0.35, 0.20), (0.80, 0.70, 0.45),
                 (0.20, 0.20, 0.22), (0.85, 0.85, 0.80), (0.50, 0.30, 0.55), (0.75, 0.45, 0.15),
                 (0.25, 0.45, 0.55), (0.60, 0.55, 0.50)]


def wall_with_holes(b: MeshBuilder, origin, direction, length, height, holes, material, cell):
    """A wall rectangle (facing into the room) minus rectangular holes ``(u0, u1, v0, v1)``."""
    us = sorted({0.0, length, *[h[0] for h in holes], *[h[1] for h in holes]})
    vs = sorted({0.0, height, *[h[2] for h in holes], *[h[3] for h in holes]})
    up = np.array([0.0, 1.0, 0.0])
    for u0, u1 in zip(us[:-1], us[1:]):
        for v0, v1 in zip(vs[:-1], vs[1:]):
            um, vm = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
            if any(h[0] < um < h[1] and h[2] < vm < h[3] for h in holes):
                continue
            o = origin + direction * u0 + up * v0
            b.add_mesh(textured_quad(o, direction * (u1 - u0), up * (v1 - v0),
                                     cells_along(u1 - u0, cell), cells_along(v1 - v0, cell)),
                       material)


def framed_picture(b: MeshBuilder, corner, direction, width, height, uv_rect, m_image, m_frame,
                    frame_w):
    """A picture on a wall: ``corner`` is the wall point at the picture's lower-left edge (seen
    from the room) at its bottom height; ``direction`` runs along the wall to the right."""
    d = np.asarray(direction, float)
    inward = np.array([-d[2], 0.0, d[0]])
    base = np.asarray(corner, float)
    o = base + inward * 0.015
    b.add_mesh(textured_quad(o, d * width, (0, height, 0), 2, 2, uv_rect), m_image)
    f = frame_w
    for a0, a1, v0, v1 in ((-f, 0, -f, height + f), (width, width + f, -f, height + f),
                           (0, width, -f, 0), (0, width, height, height + f)):
        p = base + d * a0 + np.array([0, v0, 0])
        span = d * (a1 - a0)
        up = np.array([0, v1 - v0, 0])
        b.add_mesh(textured_quad(p + inward * 0.022, span, up, 1, 1), m_frame)
        # sides of the frame's thickness
        b.add_mesh(textured_quad(p, span, inward * 0.022, 1, 1), m_frame)
        b.add_mesh(textured_quad(p + up, inward * 0.022, span, 1, 1), m_frame)


def chair(b: MeshBuilder, xz, yaw, m_chair, m_fabric, seat_colour):
    """A chair facing ``yaw`` (0 = facing +z) at floor position ``xz``."""
    x, z = xz
    leg_colour = (0.16, 0.16, 0.17)
    pivot = (x, 0.0, z)
    s = 0.22
    b.add_mesh(box_mesh((x - s, 0.44, z - s), (x + s, 0.49, z + s), cell=1, yaw=yaw, pivot=pivot),
               m_fabric, seat_colour)
    for lx, lz in ((-s + 0.02, -s + 0.02), (s - 0.05, -s + 0.02), (-s + 0.02, s - 0.05),
                   (s - 0.05, s - 0.05)):
        b.add_mesh(box_mesh((x + lx, 0, z + lz), (x + lx + 0.03, 0.44, z + lz + 0.03), cell=1,
                            yaw=yaw, pivot=pivot, skip=("-y", "+y")), m_chair, leg_colour)
    for lx in (-s + 0.02, s - 0.05):
        b.add_mesh(box_mesh((x + lx, 0.49, z - s + 0.005), (x + lx + 0.03, 0.9, z - s + 0.03),
                            cell=1, yaw=yaw, pivot=pivot), m_chair, leg_colour)
    b.add_mesh(box_mesh((x - s, 0.62, z - s - 0.005), (x + s, 0.88, z - s + 0.025), cell=1,
                        yaw=yaw, pivot=pivot), m_fabric, seat_colour)


def bookshelf(b: MeshBuilder, rng, wall_xz, yaw, width, height, depth, m_shelf, m_books):
    """An open bookshelf standing against a wall. ``wall_xz``: the wall point behind the
    shelf's centre; ``yaw``: 0 for the north wall (shelf opening towards +z), pi/2 for the
    west wall (opening towards +x)."""
    x, z = wall_xz
    pivot = (x, 0.0, z)
    w2 = 0.5 * width
    t = 0.02
    z0 = z + 0.01
    z1 = z0 + depth

    def add(lo, hi, m, colour=None):
        b.add_mesh(box_mesh(lo, hi, cell=0.5, yaw=yaw, pivot=pivot), m, colour)

    add((x - w2, 0, z0), (x - w2 + t, height, z1), m_shelf)
    add((x + w2 - t, 0, z0), (x + w2, height, z1), m_shelf)
    add((x - w2, height - t, z0), (x + w2, height, z1), m_shelf)
    add((x - w2, 0, z0), (x + w2, 0.08, z1), m_shelf)
    add((x - w2, 0, z0), (x + w2, height, z0 + 0.01), m_shelf)
    n_shelves = 5
    levels = np.linspace(0.08, height - t, n_shelves + 1)
    for y in levels[1:-1]:
        add((x - w2 + t, y - t, z0), (x + w2 - t, y, z1), m_shelf)
    for y0, y1 in zip(levels[:-1], levels[1:]):
        bx = x - w2 + t + rng.uniform(0.0, 0.06)
        end = x + w2 - t - rng.uniform(0.0, 0.15)
        while bx < end - 0.02:
            bw = rng.uniform(0.018, 0.05)
            if rng.random() < 0.08:  # a gap
                bx += rng.uniform(0.05, 0.15)
                continue
            bh = min(rng.uniform(0.6, 0.92) * (y1 - y0 - t), y1 - y0 - t - 0.01)
            bd = rng.uniform(0.6, 0.95) * depth
            colour = np.array(_BOOK_COLOURS[int(rng.integers(len(_BOOK_COLOURS)))])
            colour = np.clip(colour * rng.uniform(0.8, 1.15), 0, 1)
            add((bx, y0, z0 + 0.01), (min(bx + bw, end), y0 + bh, z0 + 0.01 + bd), m_books,
                colour)
            bx += bw + rng.uniform(0.0, 0.004)
