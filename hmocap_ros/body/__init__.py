"""Skinned body model: kinematic tree, forward kinematics, linear blend skinning, anthropometry (thesis sec. 2.3).

Modules: ``skeleton`` (DoFs, limits, pose <-> local rotations, eq. 2.11) with its
``dof_table``, ``kinematics`` (batched FK and LBS, eq. 2.12), ``entities`` (table 2.1),
``shape_deformation`` (bone/radial scale deformation of sec. 2.3.2), ``anthropometry``
(shapes, entity sizes and priors, eq. 2.13), ``model`` (the shipped MakeHuman CC0 assets).
"""
from .anthropometry import (
                            ENTITIES,
                            ENTITY_NAMES,
                            TABLE_2_1,
                            BodyShape,
                            apply_shape,
                            entity_priors,
                            entity_sizes,
                            sample_shape,
                            shape_log_prior,
)
from .kinematics import SparseWeights, end_site_positions, forward_kinematics, skin_vertices, skinning_matrices
from .model import BodyModel, PoseResult, load_body_model, read_body_model
from .skeleton import (
                            Skeleton,
                            build_skeleton,
                            clip_pose,
                            local_rotations_to_pose,
                            pose_to_local_rotations,
                            rest_pose,
                            sample_pose,
)

__all__ = [
    "ENTITIES", "ENTITY_NAMES", "TABLE_2_1", "BodyShape", "apply_shape", "entity_priors",
    "entity_sizes", "sample_shape", "shape_log_prior", "SparseWeights", "end_site_positions",
    "forward_kinematics", "skin_vertices", "skinning_matrices", "BodyModel", "PoseResult",
    "load_body_model", "read_body_model", "Skeleton", "build_skeleton", "clip_pose",
    "local_rotations_to_pose", "pose_to_local_rotations", "rest_pose", "sample_pose",
]
