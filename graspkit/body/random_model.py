"""A random, dense SMPL-X-format model: for parity tests and benchmarks, not a body.

Every array has the real layout and non-zero content (pose correctives included), so the parts of
an LBS engine that the procedural humanoid leaves at zero are exercised too.
"""
from __future__ import annotations

import numpy as np

from graspkit.body.skeleton import NUM_JOINTS, PARENTS
from graspkit.checks import seeded_rng


def random_smplx_arrays(num_vertices: int = 10475, num_faces: int = 20908, seed: int = 0,
                        sparse_weights: int = 4) -> dict[str, np.ndarray]:
    """Arrays of a random SMPL-X-format model with V vertices; weights have `sparse_weights` joints per vertex."""
    rng = seeded_rng(seed)
    V = num_vertices
    v = rng.normal(scale=0.3, size=(V, 3))
    weights = np.zeros((V, NUM_JOINTS))
    cols = np.stack([rng.choice(NUM_JOINTS, sparse_weights, replace=False) for _ in range(V)])
    np.put_along_axis(weights, cols, rng.random((V, sparse_weights)) + 0.1, axis=1)
    weights /= weights.sum(1, keepdims=True)
    J_reg = rng.random((NUM_JOINTS, V)) * (rng.random((NUM_JOINTS, V)) < 0.002)
    J_reg[:, 0] += 1e-3  # no empty row
    J_reg /= J_reg.sum(1, keepdims=True)
    hands = [np.linalg.qr(rng.normal(size=(45, 45)))[0].T for _ in range(2)]
    return {
        "v_template": v, "f": rng.integers(0, V, size=(num_faces, 3)).astype(np.int32),
        "shapedirs": rng.normal(scale=0.01, size=(V, 3, 20)),
        "posedirs": rng.normal(scale=0.002, size=(V, 3, 486)),
        "J_regressor": J_reg, "weights": weights,
        "kintree_table": np.stack([np.array([4294967295] + list(PARENTS[1:]), np.int64), np.arange(NUM_JOINTS)]),
        "hands_componentsl": hands[0], "hands_componentsr": hands[1],
        "hands_meanl": rng.normal(scale=0.2, size=45), "hands_meanr": rng.normal(scale=0.2, size=45),
        "lmk_faces_idx": np.arange(51, dtype=np.int64), "lmk_bary_coords": np.full((51, 3), 1 / 3),
        "dynamic_lmk_faces_idx": np.zeros((79, 17), np.int64), "dynamic_lmk_bary_coords": np.full((79, 17, 3), 1 / 3),
    }
