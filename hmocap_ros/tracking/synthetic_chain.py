"""A synthetic kinematic-tree objective for testing layered particle filters (24 dims).

A small articulated "body": a root block (3 translation + 3 rotation-vector dims) and six
3-dof ball joints (spine, head, two upper arms, two forearms) chained by forward kinematics,
so an error in a parent block moves every marker below it. Each block carries markers; the
cost of a particle is

    sum over markers of |y(x) - y*|^2 / marker_sigma^2
  + ripple * sum over dims of (1 - cos(2 pi (x - x*) / ripple_period))

The cosine ripple puts a local minimum every ``ripple_period`` radians (metres for the
translation) in each dimension around the true pose ``x*``, so the landscape is multimodal
like a silhouette XOR cost, and the hierarchy lets a layer's weighting measure only the
blocks filtered so far (partitioned sampling, thesis sec. 2.2.3).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# block: (parent block, joint offset from the parent joint in the parent frame (m),
#         marker offsets in the block frame (m))
_BLOCKS = (
    ("root", -1, (0.0, 0.0, 0.0), ((0.0, 0.0, 0.0), (0.15, 0.0, 0.0), (0.0, 0.0, 0.12))),
    ("spine", 0, (0.0, 0.1, 0.0), ((0.0, 0.45, 0.0), (0.12, 0.45, 0.0))),
    ("head", 1, (0.0, 0.5, 0.0), ((0.0, 0.22, 0.0), (0.0, 0.1, 0.1))),
    ("l_upper_arm", 1, (0.18, 0.42, 0.0), ((0.3, 0.0, 0.0), (0.3, 0.0, 0.06))),
    ("l_forearm", 3, (0.3, 0.0, 0.0), ((0.27, 0.0, 0.0), (0.27, 0.06, 0.0))),
    ("r_upper_arm", 1, (-0.18, 0.42, 0.0), ((-0.3, 0.0, 0.0), (-0.3, 0.0, 0.06))),
    ("r_forearm", 5, (-0.3, 0.0, 0.0), ((-0.27, 0.0, 0.0), (-0.27, 0.06, 0.0))),
)
BLOCK_NAMES = tuple(b[0] for b in _BLOCKS)
BLOCK_DIMS = (np.arange(0, 6),) + tuple(np.arange(6 + 3 * i, 9 + 3 * i)
                                        for i in range(len(_BLOCKS) - 1))
N_DIMS = 6 + 3 * (len(_BLOCKS) - 1)


def _rotvec_to_matrix(v: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for a batch of rotation vectors (N, 3) -> (N, 3, 3)."""
    theta = np.linalg.norm(v, axis=-1)
    safe = np.where(theta < 1e-9, 1.0, theta)
    a = np.where(theta < 1e-9, 1.0, np.sin(safe) / safe)
    b = np.where(theta < 1e-9, 0.5, (1.0 - np.cos(safe)) / safe**2)
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    zero = np.zeros_like(x)
    k = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                  np.stack([-y, x, zero], -1)], -2)
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * (k @ k)


def chain_markers(params: np.ndarray, n_blocks: int = len(_BLOCKS)) -> list[np.ndarray]:
    """Forward kinematics of the first ``n_blocks`` blocks: a list of (N, K_b, 3) markers.

    Blocks are in tree order (parents first), so a prefix of the tree needs no other block.
    """
    params = np.atleast_2d(params)
    rot, pos, markers = [], [], []
    for i, (_, parent, offset, marks) in enumerate(_BLOCKS[:n_blocks]):
        local = _rotvec_to_matrix(params[:, BLOCK_DIMS[i][-3:]])
        if parent < 0:
            r, p = local, params[:, :3]
        else:
            r = rot[parent] @ local
            p = pos[parent] + rot[parent] @ np.asarray(offset)
        rot.append(r)
        pos.append(p)
        markers.append(p[:, None, :] + np.einsum("nij,kj->nki", r, np.asarray(marks)))
    return markers


@dataclass(frozen=True, eq=False)
class ChainProblem:
    """One instance: the true pose, the initial particle cloud's centre and spread."""

    truth: np.ndarray          # (D,) x*
    start: np.ndarray          # (D,) centre of the initial particles (a wrong previous pose)
    sigma: np.ndarray          # (D,) spread of the start error and of the initial cloud
    marker_sigma: float = 0.03
    ripple: float = 1.0
    ripple_period: float = 0.5

    def __post_init__(self):
        object.__setattr__(self, "_truth_markers", chain_markers(self.truth[None]))

    def block_costs(self, particles: np.ndarray, n_blocks: int) -> np.ndarray:
        """Cost of the first ``n_blocks`` blocks (tree order) for every particle, (N,)."""
        cost = np.zeros(particles.shape[0])
        for m, t in zip(chain_markers(particles, n_blocks), self._truth_markers):
            cost += np.sum((m - t) ** 2, axis=(1, 2)) / self.marker_sigma**2
        dims = np.concatenate(BLOCK_DIMS[:n_blocks])
        phase = 2.0 * np.pi * (particles[:, dims] - self.truth[dims]) / self.ripple_period
        cost += self.ripple * np.sum(1.0 - np.cos(phase), axis=1)
        return cost

    def cost(self, particles: np.ndarray, layer_index: int = 0) -> np.ndarray:
        """Full cost: the weighting function of every APF layer."""
        return self.block_costs(particles, len(_BLOCKS))

    def hierarchical_cost(self, layers_per_block: int = 1):
        """Weighting function of the HPF: layer l measures blocks 0 .. l // layers_per_block."""
        def weight_fn(particles: np.ndarray, layer_index: int) -> np.ndarray:
            n = min(layer_index // layers_per_block + 1, len(_BLOCKS))
            return self.block_costs(particles, n)
        return weight_fn

    def marker_error(self, params: np.ndarray) -> np.ndarray:
        """Mean marker distance to the truth (m) of poses (N, D) -> (N,): the "3D error"."""
        markers = chain_markers(np.atleast_2d(params))
        d = [np.linalg.norm(m - t, axis=-1) for m, t in zip(markers, self._truth_markers)]
        return np.concatenate(d, axis=1).mean(axis=1)

    def initial_particles(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """N particles around ``start``: a previous-frame cloud the filter starts from."""
        return self.start + rng.standard_normal((n, self.truth.size)) * self.sigma


def make_chain_problem(rng: np.random.Generator, rotation_sigma: float = 0.35,
                       translation_sigma: float = 0.08, **kwargs) -> ChainProblem:
    """A random instance: a random true pose, and a start displaced by one ``sigma`` draw."""
    sigma = np.full(N_DIMS, rotation_sigma)
    sigma[:3] = translation_sigma
    truth = rng.normal(0.0, 0.5, N_DIMS)
    truth[:3] = rng.normal(0.0, 0.3, 3)
    start = truth + rng.standard_normal(N_DIMS) * sigma
    return ChainProblem(truth=truth, start=start, sigma=sigma, **kwargs)
