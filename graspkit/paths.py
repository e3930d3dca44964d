"""Where graspkit finds its shipped files (data_stubs/) and writes caches."""
from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_STUBS = REPO_ROOT / "data_stubs"
BODY_MODELS = DATA_STUBS / "body_models"


def default_model_path() -> Path:
    """The SMPL-X-format model to use: $GRASPKIT_MODEL if set, else the shipped procedural humanoid."""
    env = os.environ.get("GRASPKIT_MODEL")
    return Path(env) if env else BODY_MODELS / "smplx" / "SMPLX_NEUTRAL.npz"


def cache_dir() -> Path:
    """Folder for generated training sets and outputs of long jobs: $GRASPKIT_CACHE or ~/.cache/graspkit."""
    return Path(os.environ.get("GRASPKIT_CACHE", Path.home() / ".cache" / "graspkit"))
