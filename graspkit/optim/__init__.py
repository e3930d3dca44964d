"""Optimisers of the workbook: grasp and motion refinement (SAGA GraspPose-Opt / GraspMotion-Opt, GOAL), latent optimisation."""
