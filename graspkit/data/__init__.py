"""Procedural motion data: AMASS-style locomotion, CIRCLE-style reaching, the reaching planner, file formats.

    from graspkit.data import Motion, generate_locomotion, generate_reach, plan_reach, Start, load_motion, save_motion
    m = plan_reach(Start(0, 0, 0), goal=(2.0, 1.0, 0.9), t_goal_frames=239)     # WANDR's time-controlled reach
    save_motion("clip.npz", m); m2 = load_motion("clip.npz")                    # AMASS-style .npz, z-up, 30 fps

Reference: docs/data.md. Modules: motion (Motion), rig (body measurements), trajectory (root plans),
footsteps (footstep planner, foot motion, contacts), ik (two-bone IK), posing (whole-body poses),
locomotion, reaching, formats, cli. Grasps (docs/grasps.md; import them from their modules): grasp (tasks, frames,
GraspFitter), grasp_opt (partial skinning, arm IK, closing fingers, polish), grasp_make (labels, files, `graspkit data
make --kind grasp|approach`), grasp_datasets (WholeGraspDataset, GNetDataset, ApproachDataset), grab (GRAB-style files),
approach (approach-and-grasp clips).
"""
from graspkit.data.formats import SequenceFileError, load_motion, save_motion
from graspkit.data.locomotion import generate_locomotion
from graspkit.data.motion import CONTACT_NAMES, Motion, canonicalize, heading_of
from graspkit.data.reaching import (Start, evaluation_goals, generate_reach, generate_reach_chain, plan_reach,
                                    plan_reach_chain)

__all__ = ["Motion", "CONTACT_NAMES", "canonicalize", "heading_of", "load_motion", "save_motion", "SequenceFileError",
           "generate_locomotion", "generate_reach", "generate_reach_chain", "plan_reach", "plan_reach_chain", "Start",
           "evaluation_goals"]
