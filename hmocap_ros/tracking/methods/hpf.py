"""HPF and HPF+APO: one layer per body block along the kinematic tree (thesis alg. 3,
sec. 2.4.1), with or without approximate partitioning of observations (eq. 2.15)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.lpf.layered_filter import Layer, LayeredFilter
from hmocap_ros.tracking.body_layers import BODY_BLOCKS, SWEEP_DECAY, BodySchedule, block_dims
from hmocap_ros.tracking.methods.base import LayeredMethod

__all__ = ["HierarchicalMethod"]


@dataclass(frozen=True)
class HierarchicalMethod(LayeredMethod):
    """The blocks of :data:`~.body_layers.BODY_BLOCKS` weighed in order, ``sweeps`` times
    per frame (:mod:`~hmocap_ros.tracking.body_layers`). boxed: each layer weighs inside the
    observation boxes of its block (eq. 2.15) and a final layer re-weighs the whole body
    (eq. 2.8); else every layer weighs the whole images and the last block's layer is the
    final one."""

    boxed: bool = False

    def layer_particles(self, sweeps: int) -> int:
        if sweeps <= 1:
            return self.particles
        # the same evaluations per frame over more layers
        total = sweeps * len(BODY_BLOCKS) + self.layers - len(BODY_BLOCKS)
        return int(round(self.layers * self.particles / total))

    def schedule(self, skel, n_particles, n_layers, sigma0, kernel, *, survival_rate,
                 apf_alpha, refine_nu, sweeps) -> BodySchedule:
        blocks = block_dims(skel)
        boxed = self.boxed
        d = skel.n_dofs
        # the blocks weighed in order, ``sweeps`` times over the kinematic tree; without
        # boxes the final whole-image layer is the last block's weighting
        order = [(s, b) for s in range(sweeps) for b in range(len(blocks))]
        if not boxed:
            order = order[:-1]

        def block_std(s: int, b: int) -> np.ndarray:
            return (SWEEP_DECAY ** s) * sigma0[blocks[b]]

        layers = []
        last_weighed: dict[int, tuple[int, int]] = {}  # block -> (layer, sweep) last weighed in
        for j, (s, b) in enumerate(order):
            last_weighed[b] = (j, s)
            std = np.zeros(d)
            if refine_nu > 0:  # alg. 3 re-diffusion of the blocks filtered so far
                for m, (k, sm) in last_weighed.items():
                    std[blocks[m]] = (refine_nu ** (j + 1 - k)) * block_std(sm, m)
            if j + 1 < len(order):  # the kernel diffuses the next block right before its layer
                s_next, b_next = order[j + 1]
                std[blocks[b_next]] = block_std(s_next, b_next)
            elif not boxed:
                std[blocks[-1]] = block_std(sweeps - 1, len(blocks) - 1)
            layers.append(Layer(dims=blocks[b], survival_rate=survival_rate,
                                n_particles=n_particles, std=std, kernel=kernel))
        final_std = np.zeros(d)
        final_std[blocks[0]] = sigma0[blocks[0]]
        final = Layer(survival_rate=survival_rate, n_particles=n_particles, std=final_std,
                      kernel=kernel)
        lpf = LayeredFilter(layers=tuple(layers), sigma0=sigma0, nu=max(refine_nu, 1e-6),
                            final=final)
        names = [(BODY_BLOCKS[b],) for _, b in order]
        final_blocks = () if boxed else (BODY_BLOCKS[-1],)
        return BodySchedule(method=self, filter=lpf,
                            layer_blocks=tuple(names) + (final_blocks,),
                            boxed=tuple([boxed] * len(order) + [False]))
