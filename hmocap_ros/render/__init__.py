"""Rendering for the tracker and the simulator (numba, CPU).

- :mod:`.silhouette`: batched binary silhouettes and the fused silhouette XOR cost
  (eq. 2.8, 2.15) for the particle filter's hot path.
- :mod:`.rasterize`: z-buffer with face ids and perspective-correct barycentrics.
- :mod:`.shading`, :mod:`.materials`, :mod:`.lights`, :mod:`.textures`, :mod:`.shadow`: RGB
  frames with procedural textures, Lambert lighting and soft shadow maps; :mod:`.sensor`:
  noise, illumination, anti-aliasing.
- :mod:`.depth`: Kinect-like uint16 depth images.
- :mod:`.reference`: slow exact numpy rasteriser that the fast ones are tested against.
All coverage follows :mod:`.scanline`: pixel centres at integer coordinates, top-left rule.
Points are projected by :func:`hmocap_ros.geometry.projection.project_batch`.
"""

from hmocap_ros.render.depth import KinectNoise, depth_to_millimetres, kinect_depth
from hmocap_ros.render.lights import DirectionalLight, Lighting, PointLight
from hmocap_ros.render.materials import Material, material_table
from hmocap_ros.render.meshes import concatenate_meshes, face_normals, grid_quad, vertex_normals
from hmocap_ros.render.rasterize import face_range_mask, interpolate, rasterize
from hmocap_ros.render.shading import shade
from hmocap_ros.render.shadow import ShadowMap, render_shadow_map
from hmocap_ros.render.silhouette import observed_counts, render_silhouettes, xor_counts

__all__ = [
    "DirectionalLight", "KinectNoise", "Lighting", "Material", "PointLight", "ShadowMap",
    "concatenate_meshes", "depth_to_millimetres", "face_normals", "face_range_mask",
    "grid_quad", "interpolate", "kinect_depth", "material_table",
    "observed_counts", "rasterize", "render_shadow_map",
    "render_silhouettes", "shade", "vertex_normals", "xor_counts",
]
