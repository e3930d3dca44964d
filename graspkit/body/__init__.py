"""The body: SMPL-X-format LBS engine, skeleton constants, the procedural humanoid and marker sets."""
from graspkit.body.model import BodyModel, BodyOutput, ModelFileError, load_model_arrays, shared_body
from graspkit.body.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS

__all__ = ["BodyModel", "BodyOutput", "ModelFileError", "load_model_arrays", "shared_body", "JOINT_NAMES", "NUM_JOINTS", "PARENTS"]
