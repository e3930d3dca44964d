"""Shared fixtures: a random dense SMPL-X-format model file in a smplx-style folder."""
from pathlib import Path

import numpy as np
import pytest

from graspkit.body.random_model import random_smplx_arrays

ROOT = Path(__file__).resolve().parents[1]
PROCEDURAL_MODEL = ROOT / "data_stubs" / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz"


@pytest.fixture(scope="session")
def random_model_dir(tmp_path_factory) -> Path:
    """A folder `<tmp>/smplx/SMPLX_NEUTRAL.npz` holding a random dense model (non-zero pose correctives)."""
    root = tmp_path_factory.mktemp("random_body_models")
    (root / "smplx").mkdir()
    np.savez(root / "smplx" / "SMPLX_NEUTRAL.npz", **random_smplx_arrays(seed=7))
    return root
