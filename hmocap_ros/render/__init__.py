"""The tracker's rendering (numba, CPU): binary silhouettes and the silhouette XOR cost.

- :mod:`.silhouette`: batched binary silhouettes and the fused silhouette XOR cost
  (eq. 2.8, 2.15) for the particle filter's hot path.
- :mod:`.fused_xor`: projection, silhouette and XOR in one pass over the particles' vertices.
All coverage follows :mod:`.scanline`: pixel centres at integer coordinates, top-left rule.
Points are projected by :func:`hmocap_ros.geometry.projection.project_batch`. The simulator's
RGB and depth rendering is :mod:`hmocap_sim.render`.
"""

from hmocap_ros.render.silhouette import observed_counts, render_silhouettes, xor_counts

__all__ = ["observed_counts", "render_silhouettes", "xor_counts"]
