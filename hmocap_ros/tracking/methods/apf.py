"""APF: the annealed particle filter over all DoFs (thesis alg. 2)."""
from __future__ import annotations

from dataclasses import dataclass

from hmocap_ros.lpf.layered_filter import Layer, LayeredFilter, annealed_filter
from hmocap_ros.tracking.body_layers import BodySchedule
from hmocap_ros.tracking.methods.base import LayeredMethod

__all__ = ["AnnealedMethod"]


@dataclass(frozen=True)
class AnnealedMethod(LayeredMethod):
    """``n_layers`` annealing layers over all DoFs (the last is the final run with the
    inter-frame kernel), beta per layer for a survival rate, the diffusion decaying by
    ``apf_alpha`` in variance per layer (eq. 2.10); the first layer weighs the particles the
    inter-frame kernel diffused (sigma0). Every layer weighs the whole images (eq. 2.8)."""

    def schedule(self, skel, n_particles, n_layers, sigma0, kernel, *, survival_rate,
                 apf_alpha, refine_nu, sweeps) -> BodySchedule:
        n_layers = int(n_layers or self.layers)
        lpf = annealed_filter(sigma0, n_layers, n_particles, alpha=apf_alpha,
                              survival_rate=survival_rate)
        layers = tuple(Layer(beta=L.beta, survival_rate=L.survival_rate,
                             n_particles=L.n_particles, std=L.std, kernel=kernel)
                       for L in lpf.layers)
        final = Layer(survival_rate=survival_rate, n_particles=n_particles, kernel=kernel)
        lpf = LayeredFilter(layers=layers, sigma0=sigma0, final=final)
        return BodySchedule(self, lpf, tuple(() for _ in range(n_layers)),
                            tuple(False for _ in range(n_layers)))
