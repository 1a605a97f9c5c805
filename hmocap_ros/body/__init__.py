"""Skinned body model: kinematic tree, forward kinematics, linear blend skinning, anthropometry (thesis sec. 2.3)."""
