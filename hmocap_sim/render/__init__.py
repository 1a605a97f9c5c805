"""The simulator's rendering (numba, CPU): RGB frames and Kinect-like depth.

- :mod:`.rasterize`: z-buffer with face ids and perspective-correct barycentrics.
- :mod:`.shading`, :mod:`.materials`, :mod:`.lights`, :mod:`.textures`, :mod:`.shadow`: RGB
  frames with procedural textures, Lambert lighting and soft shadow maps; :mod:`.sensor`:
  noise, illumination, anti-aliasing.
- :mod:`.depth`: Kinect-like uint16 depth images.
- :mod:`.reference`: slow exact numpy rasteriser that the fast ones (these and the tracker's
  :mod:`hmocap_ros.render.silhouette`) are tested against.
All coverage follows :mod:`hmocap_ros.render.scanline`: pixel centres at integer coordinates,
top-left rule. Points are projected by :func:`hmocap_ros.geometry.projection.project_batch`.
"""

from hmocap_sim.render.depth import KinectNoise, depth_to_millimetres, kinect_depth
from hmocap_sim.render.lights import DirectionalLight, Lighting, PointLight
from hmocap_sim.render.materials import Material, material_table
from hmocap_sim.render.meshes import concatenate_meshes, face_normals, grid_quad, vertex_normals
from hmocap_sim.render.rasterize import face_range_mask, interpolate, rasterize
from hmocap_sim.render.shading import shade
from hmocap_sim.render.shadow import ShadowMap, render_shadow_map

__all__ = [
    "DirectionalLight", "KinectNoise", "Lighting", "Material", "PointLight", "ShadowMap",
    "concatenate_meshes", "depth_to_millimetres", "face_normals", "face_range_mask",
    "grid_quad", "interpolate", "kinect_depth", "material_table", "rasterize",
    "render_shadow_map", "shade", "vertex_normals",
]
