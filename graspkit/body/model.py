"""BodyModel: SMPL-X-format linear blend skinning (Pavlakos et al., CVPR 2019, Sec. 3; SMPL Eq. 1-10).

    T(beta, psi, theta) = T_bar + B_S(beta; S) + B_E(psi; E) + B_P(theta; P)     (shape, expression, pose blend shapes)
    J(beta, psi)        = J_reg @ (T_bar + B_S + B_E)                          (joints regressed from the shaped mesh)
    v_i                 = sum_k w_ik G_k(theta, J) G_k(0, J)^-1 T_i           (linear blend skinning)

The engine reads any file in the SMPL-X `.npz` layout: graspkit's procedural humanoid or a real
SMPLX_{NEUTRAL,MALE,FEMALE}.npz. Everything that does not depend on the pose is precomputed once:
the joint regressor is folded into the template and the shape basis (J = J_0 + coeffs @ J_dirs), so
the forward pass never touches the dense (55, V) regressor, and the kinematic chain is walked one tree
level at a time (11 batched matmuls instead of 54 sequential ones). The skinning is one GEMM (the 12 entries
of the 55 joint transforms against the weights) per chunk of bodies small enough to stay in the caches.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from torch import Tensor, nn

from graspkit.body.skeleton import NUM_BODY_JOINTS, NUM_JOINTS
from graspkit.rotations import axis_angle_to_matrix

NUM_HAND_JOINTS = 15
NUM_POSE_BASIS = (NUM_JOINTS - 1) * 9  # 486
SKIN_CHUNK_BYTES = 16 * 2**20          # the skinning runs over bodies in chunks whose (n,12,V) transforms fit this


@dataclass
class BodyOutput:
    """What a forward pass returns: vertices (B,V,3), joints (B,55,3), faces (F,3) and the full pose (B,55,3,3)."""

    vertices: Tensor
    joints: Tensor
    faces: Tensor
    rot_mats: Tensor


class ModelFileError(ValueError):
    """A body-model file that is missing, pickled, or has a wrong key, shape or dtype."""


def _expected_shapes(V: int) -> dict[str, tuple[int | None, ...]]:
    """Expected shape per required key for a model with V vertices (None = any size)."""
    return {
        "v_template": (V, 3), "f": (None, 3), "shapedirs": (V, 3, None), "posedirs": (V, 3, NUM_POSE_BASIS),
        "J_regressor": (NUM_JOINTS, V), "weights": (V, NUM_JOINTS), "kintree_table": (2, NUM_JOINTS),
        "hands_componentsl": (45, 45), "hands_componentsr": (45, 45), "hands_meanl": (45,), "hands_meanr": (45,),
    }


def _read_pickled_model(path: Path) -> dict[str, object]:
    """The dict of an official SMPL-X .pkl (Python-2 pickle; only ever read behind allow_pickle=True)."""
    import pickle  # only here: the explicit opt-in for real third-party files

    with open(path, "rb") as fh:
        try:
            data = pickle.load(fh, encoding="latin1")
        except Exception as e:
            raise ModelFileError(f"{path}: not a readable pickled body model ({e})") from None
    if not isinstance(data, dict):
        raise ModelFileError(f"{path}: expected a pickled dict of SMPL-X arrays, got {type(data).__name__}")
    # SMPL(-X) .pkl files may hold the regressor as a scipy sparse matrix
    return {k: (v.toarray() if hasattr(v, "toarray") else v) for k, v in data.items()}


def load_model_arrays(path: str | os.PathLike, allow_pickle: bool = False) -> dict[str, np.ndarray]:
    """Read and validate the arrays of an SMPL-X-format .npz (or, with allow_pickle=True, an official .pkl).

    Errors name the file, key and expectation."""
    path = Path(path)
    if path.is_dir():
        found = sorted(p.name for p in path.glob("*.npz"))
        raise ModelFileError(f"{path}: is a directory; pass the body-model file itself (expected an SMPL-X-format "
                             f".npz such as SMPLX_NEUTRAL.npz; .npz files here: {found or 'none'})")
    if not path.is_file():
        from graspkit.paths import stub_hint

        raise ModelFileError(f"{path}: no such body-model file (expected an SMPL-X-format .npz){stub_hint(path)}")
    with open(path, "rb") as fh:
        head = fh.read(6)
    pickled = head[:1] == b"\x80"
    if not pickled and not head.startswith((b"PK\x03\x04", b"PK\x05\x06", b"\x93NUMPY")):
        raise ModelFileError(f"{path}: not an .npz body model (expected an SMPL-X-format .npz archive of arrays)")
    if pickled and not allow_pickle:
        raise ModelFileError(f"{path}: a pickled file; graspkit reads plain .npz files only "
                             "(pass allow_pickle=True explicitly for a trusted third-party file)")
    if pickled:
        source: Mapping[str, object] = _read_pickled_model(path)
        keys = set(source)
    else:
        try:
            npz = np.load(path, allow_pickle=allow_pickle)
        except Exception as e:
            raise ModelFileError(f"{path}: not a readable .npz file ({e})") from None
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise ModelFileError(f"{path}: expected an .npz archive of arrays, got a single array")
        source, keys = npz, set(npz.files)
    try:
        if "v_template" not in keys:
            raise ModelFileError(f"{path}: missing key 'v_template' (an SMPL-X .npz has {sorted(_expected_shapes(0))})")
        arrays: dict[str, np.ndarray] = {}
        optional = [k for k in ("procedural",) if k in keys]
        for key in [*_expected_shapes(0), *optional]:
            if key not in keys:
                raise ModelFileError(f"{path}: missing key {key!r}")
            try:
                arrays[key] = np.asarray(source[key])
            except ValueError as e:
                raise ModelFileError(f"{path}: key {key!r} cannot be read without pickle ({e})") from None
            except Exception as e:      # a damaged member: BadZipFile (CRC), zlib.error, EOFError
                raise ModelFileError(f"{path}: key {key!r} is corrupt ({type(e).__name__}: {e})") from None
    finally:
        if isinstance(source, np.lib.npyio.NpzFile):
            source.close()
    validate_model_arrays(arrays, source=str(path))
    return arrays


def validate_model_arrays(arrays: Mapping[str, np.ndarray], source: str = "<arrays>") -> None:
    """Check keys, shapes, dtypes and finiteness of SMPL-X arrays; raise ModelFileError naming the key."""
    if "v_template" not in arrays:
        raise ModelFileError(f"{source}: missing key 'v_template'")
    V = int(np.shape(arrays["v_template"])[0])
    for key, shape in _expected_shapes(V).items():
        if key not in arrays:
            raise ModelFileError(f"{source}: missing key {key!r}")
        a = arrays[key]
        ok = a.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, a.shape))
        if not ok:
            want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
            raise ModelFileError(f"{source}: key {key!r} has shape {a.shape}, expected {want} (V={V})")
        if a.dtype == object:
            raise ModelFileError(f"{source}: key {key!r} is an object array; expected numbers")
        if key in ("f", "kintree_table"):
            if not np.issubdtype(a.dtype, np.integer):
                raise ModelFileError(f"{source}: key {key!r} has dtype {a.dtype}, expected integers")
        elif not np.issubdtype(a.dtype, np.floating) or not np.isfinite(a).all():
            raise ModelFileError(f"{source}: key {key!r} must hold finite floats (dtype {a.dtype})")
    if arrays["shapedirs"].shape[2] < 20:
        raise ModelFileError(f"{source}: key 'shapedirs' has {arrays['shapedirs'].shape[2]} components, "
                             "expected at least 20 (10 shape + 10 expression)")
    sums = np.asarray(arrays["weights"], np.float64).sum(1)
    if V and np.abs(sums - 1).max() > 1e-3:       # LBS blends rotations: weights that do not sum to 1 scale the body
        k = int(np.abs(sums - 1).argmax())
        raise ModelFileError(f"{source}: key 'weights' row {k} sums to {sums[k]:.4f}; expected each vertex's skinning "
                             "weights to sum to 1")
    f = arrays["f"]
    if f.size and (f.min() < 0 or f.max() >= V):
        raise ModelFileError(f"{source}: key 'f' indexes vertices outside [0, {V})")
    parents = _parents(arrays["kintree_table"])
    if parents[0] != -1 or any(not (0 <= p < i) for i, p in enumerate(parents[1:], 1)):
        raise ModelFileError(f"{source}: key 'kintree_table' is not a tree with parents before children")


def _parents(kintree: np.ndarray) -> list[int]:
    """Parent index per joint from a (2, J) kintree table; the root's parent becomes -1."""
    p = [int(x) for x in np.asarray(kintree[0]).astype(np.int64)]
    p[0] = -1
    return p


def _split_shapedirs(shapedirs: np.ndarray, num_betas: int, num_expression: int) -> tuple[np.ndarray, np.ndarray]:
    """Shape and expression bases (V,3,S), (V,3,E) from the stacked shapedirs, as smplx reads them."""
    total = shapedirs.shape[2]
    shape_space, expr_start = (300, 300) if total >= 400 else (10, 10)  # SMPL-X 2020 (300+100) or v1.1 (10+10)
    if not 0 <= num_betas <= shape_space:
        raise ValueError(f"num_betas: expected 0..{shape_space} for this file, got {num_betas}")
    if not 0 <= num_expression <= total - expr_start:
        raise ValueError(f"num_expression: expected 0..{total - expr_start} for this file, got {num_expression}")
    return shapedirs[:, :, :num_betas], shapedirs[:, :, expr_start:expr_start + num_expression]


class BodyModel(nn.Module):
    """An SMPL-X body: any omitted argument of forward() is zeros; batch size from the given arguments."""

    # buffers, registered in __init__ (declared for type checkers)
    v_template: Tensor
    _v_template_cm: Tensor
    shape_basis: Tensor
    J_template: Tensor
    J_basis: Tensor
    J_regressor: Tensor
    _pose_rows: Tensor
    posedirs: Tensor
    _posedirs_used: Tensor
    lbs_weights: Tensor
    _weights_t: Tensor
    faces: Tensor
    parents: Tensor
    left_hand_components: Tensor
    right_hand_components: Tensor
    hands_mean: Tensor
    pose_mean: Tensor

    def __init__(self, arrays: Mapping[str, np.ndarray], *, num_betas: int = 10, num_expression: int = 10,
                 use_pca: bool = False, num_pca_comps: int = 6, flat_hand_mean: bool = False,
                 dtype: torch.dtype = torch.float32, source: str = "<arrays>") -> None:
        super().__init__()
        if not isinstance(arrays, Mapping):
            hint = "; to load a model file use BodyModel.from_file(path)" if isinstance(arrays, (str, os.PathLike)) else ""
            raise TypeError(f"arrays: expected a mapping of SMPL-X arrays (name -> array), got {type(arrays).__name__}{hint}")
        validate_model_arrays(arrays, source)
        for name, v in (("num_betas", num_betas), ("num_expression", num_expression), ("num_pca_comps", num_pca_comps)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise TypeError(f"{name}: expected an int, got {v!r}")
        if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
            raise TypeError(f"dtype: expected a floating-point torch dtype such as torch.float32, got {dtype!r}")
        if use_pca and not 1 <= num_pca_comps <= 45:
            raise ValueError(f"num_pca_comps: expected 1..45, got {num_pca_comps}")
        self.source, self.use_pca, self.flat_hand_mean = source, use_pca, flat_hand_mean
        self.num_betas, self.num_expression = num_betas, num_expression
        self.num_pca_comps = num_pca_comps if use_pca else 45
        self.is_procedural = "procedural" in arrays
        t = lambda a: torch.as_tensor(np.asarray(a, dtype=np.float64), dtype=dtype)  # noqa: E731

        v_template = np.asarray(arrays["v_template"], np.float64)
        V = v_template.shape[0]
        sdirs, edirs = _split_shapedirs(np.asarray(arrays["shapedirs"], np.float64), num_betas, num_expression)
        basis = np.concatenate([sdirs, edirs], axis=2)                      # (V, 3, S+E)
        J_reg = np.asarray(arrays["J_regressor"], np.float64)
        # vertex quantities are kept coordinate-major, (3, V), so that skinning works on contiguous slabs
        self.register_buffer("v_template", t(v_template))
        self.register_buffer("_v_template_cm", t(v_template.T.reshape(1, 3 * V)))
        S = basis.shape[2]                                                   # 0 with no betas and no expression
        self.register_buffer("shape_basis", t(basis.transpose(2, 1, 0).reshape(S, 3 * V)))    # (S+E, 3V)
        # einsum's own loop, not a threaded BLAS product: the same bits whatever the thread count (digest() hashes them)
        self.register_buffer("J_template", t(np.einsum("jv,vc->jc", J_reg, v_template)))    # (55, 3)
        self.register_buffer("J_basis", t(np.einsum("jv,vkc->cjk", J_reg, basis).reshape(S, 3 * NUM_JOINTS)))
        self.register_buffer("J_regressor", t(J_reg))
        posedirs = np.asarray(arrays["posedirs"], np.float64).transpose(2, 1, 0).reshape(NUM_POSE_BASIS, 3 * V)
        # only the rows of the 486 that are not zero take part (the procedural humanoid corrects a few joints;
        # all-zero correctives cost nothing); a real SMPL-X file keeps all of them
        rows = np.flatnonzero(np.any(posedirs != 0, axis=1))
        self.has_posedirs = len(rows) > 0
        self.register_buffer("_pose_rows", torch.as_tensor(rows, dtype=torch.long))
        self.register_buffer("posedirs", t(posedirs) if self.has_posedirs else torch.zeros(0, dtype=dtype))  # (486, 3V)
        self.register_buffer("_posedirs_used", t(posedirs[rows]) if len(rows) < NUM_POSE_BASIS else self.posedirs)
        self.register_buffer("lbs_weights", t(arrays["weights"]))                          # (V, 55)
        self.register_buffer("_weights_t", t(np.asarray(arrays["weights"]).T))              # (55, V)
        self.register_buffer("faces", torch.as_tensor(np.asarray(arrays["f"], np.int64)))
        parents = _parents(arrays["kintree_table"])
        self.register_buffer("parents", torch.tensor(parents, dtype=torch.long))
        comps = [np.asarray(arrays[f"hands_components{s}"], np.float64)[:self.num_pca_comps] for s in "lr"]
        self.register_buffer("left_hand_components", t(comps[0]))
        self.register_buffer("right_hand_components", t(comps[1]))
        hands_mean = np.concatenate([np.asarray(arrays[f"hands_mean{s}"], np.float64) for s in "lr"])
        # the file's mean hands (90,), whatever flat_hand_mean says (marker placement uses them); not in state_dict,
        # so digest() is unchanged by it
        self.register_buffer("hands_mean", t(hands_mean), persistent=False)
        hands = np.zeros(90) if flat_hand_mean else hands_mean
        self.register_buffer("pose_mean", t(np.concatenate([np.zeros(3 * 25), hands])))
        self._build_levels(parents)

    def _build_levels(self, parents: list[int]) -> None:
        """Order joints by tree depth: each level is a contiguous run whose parents all sit in the level before."""
        depth = [0] * len(parents)
        for j in range(1, len(parents)):
            depth[j] = depth[parents[j]] + 1
        levels = [[j for j in range(len(parents)) if depth[j] == d] for d in range(max(depth) + 1)]
        order = [j for lv in levels for j in lv]
        self._order = torch.tensor(order)
        self._spans = [(sum(map(len, levels[:d])), sum(map(len, levels[:d + 1]))) for d in range(len(levels))]
        # the parent of each joint of level d, as a position within level d-1
        self._parent_slot = [torch.tensor([levels[d - 1].index(parents[j]) for j in lv]) if d else torch.zeros(0)
                             for d, lv in enumerate(levels)]
        self._unorder = torch.tensor(np.argsort(order))  # level order -> joint order

    @classmethod
    def from_file(cls, path: str | os.PathLike, *, allow_pickle: bool = False, **kwargs: Any) -> "BodyModel":
        """Load an SMPL-X-format .npz (procedural or real) and build the model; kwargs go to __init__."""
        return cls(load_model_arrays(path, allow_pickle=allow_pickle), source=str(path), **kwargs)

    @property
    def dtype(self) -> torch.dtype:
        return self.v_template.dtype

    @property
    def num_vertices(self) -> int:
        return self.v_template.shape[0]

    def digest(self) -> str:
        """A short hash of every array of the model (template, bases, regressor, weights, faces, pose correctives)
        and their dtype: caches of what a body model computed (motion windows, WANDR clip sets) are keyed by it."""
        import hashlib

        h = hashlib.blake2b(digest_size=6)
        for name, b in sorted(self.state_dict().items()):
            h.update(f"{name}:{b.dtype}:{tuple(b.shape)};".encode())
            h.update(b.detach().cpu().contiguous().numpy().tobytes())
        return h.hexdigest()

    # ------------------------------------------------------------------ inputs
    def _arg(self, x: Tensor | None, name: str, sizes: tuple[int, ...], B: int) -> Tensor:
        """Check one argument: (B, *sizes) or (B, prod(sizes)); None -> zeros; returns (B, prod(sizes))."""
        n = int(np.prod(sizes))
        if x is None:
            return self.v_template.new_zeros(B, n)
        if not isinstance(x, Tensor):
            raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
        if x.dim() == len(sizes) + 1 and tuple(x.shape[1:]) == sizes:
            x = x.reshape(x.shape[0], n)
        elif x.dim() == 3 and sizes[-1] == 3 and x.shape[2] == 3 and 3 * x.shape[1] == n:
            x = x.reshape(x.shape[0], n)                       # (B, 1, 3) for one joint, as smplx accepts
        if x.dim() != 2 or x.shape[1] != n:
            want = f"(B, {n})" + (f" or (B, {', '.join(map(str, sizes))})" if len(sizes) > 1 else "")
            raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")
        if x.device != self.v_template.device:
            raise ValueError(f"{name}: on {x.device}, but the model is on {self.v_template.device}")
        if x.shape[0] != B:
            x = x.expand(B, n)  # only size 1 reaches here (checked in _batch_size)
        return x.to(self.dtype)

    def _coeffs(self, x: Tensor | None, name: str, n: int, B: int) -> Tensor:
        """Betas / expression (B, k<=n), zero-padded to (B, n)."""
        if x is None:
            return self.v_template.new_zeros(B, n)
        if not isinstance(x, Tensor):
            raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
        if x.dim() != 2 or x.shape[1] > n:
            raise ValueError(f"{name}: expected shape (B, k) with k <= {n}, got {tuple(x.shape)}")
        x = self._arg(x, name, (x.shape[1],), B)
        return torch.nn.functional.pad(x, (0, n - x.shape[1])) if x.shape[1] < n else x

    @staticmethod
    def _batch_size(named: dict[str, Tensor | None]) -> int:
        """Common batch size of the given arguments (size 1 broadcasts); error names the odd one."""
        for k, v in named.items():
            if isinstance(v, Tensor) and v.dim() < 2:
                raise ValueError(f"{k}: expected a batch (B, ...) with a leading batch dimension, got shape "
                                 f"{tuple(v.shape)} (for one body: {k}[None])")
            if isinstance(v, Tensor) and v.shape[0] == 0:
                raise ValueError(f"{k}: expected a batch of at least one body, got shape {tuple(v.shape)}")
        sizes = {k: v.shape[0] for k, v in named.items() if isinstance(v, Tensor)}
        big = {s for s in sizes.values() if s != 1}
        if len(big) > 1:
            raise ValueError(f"batch sizes differ: {sizes}")
        return big.pop() if big else 1

    # ------------------------------------------------------------------ forward
    def forward(self, betas: Tensor | None = None, expression: Tensor | None = None,
                global_orient: Tensor | None = None, body_pose: Tensor | None = None,
                left_hand_pose: Tensor | None = None, right_hand_pose: Tensor | None = None,
                jaw_pose: Tensor | None = None, leye_pose: Tensor | None = None,
                reye_pose: Tensor | None = None, transl: Tensor | None = None) -> BodyOutput:
        """SMPL-X forward from axis-angle parameters; see the module docstring for the equations."""
        named = dict(betas=betas, expression=expression, global_orient=global_orient, body_pose=body_pose,
                     left_hand_pose=left_hand_pose, right_hand_pose=right_hand_pose, jaw_pose=jaw_pose,
                     leye_pose=leye_pose, reye_pose=reye_pose, transl=transl)
        B = self._batch_size(named)
        hand = (self.num_pca_comps,) if self.use_pca else (NUM_HAND_JOINTS, 3)
        lh = self._arg(left_hand_pose, "left_hand_pose", hand, B)
        rh = self._arg(right_hand_pose, "right_hand_pose", hand, B)
        if self.use_pca:
            lh, rh = lh @ self.left_hand_components, rh @ self.right_hand_components
        pose = torch.cat([self._arg(global_orient, "global_orient", (3,), B),
                          self._arg(body_pose, "body_pose", (NUM_BODY_JOINTS, 3), B),
                          self._arg(jaw_pose, "jaw_pose", (3,), B), self._arg(leye_pose, "leye_pose", (3,), B),
                          self._arg(reye_pose, "reye_pose", (3,), B), lh, rh], dim=1) + self.pose_mean
        coeffs = torch.cat([self._coeffs(betas, "betas", self.num_betas, B),
                            self._coeffs(expression, "expression", self.num_expression, B)], dim=1)
        t = self._arg(transl, "transl", (3,), B)
        self._check_finite(named, pose, coeffs, t)
        rot = axis_angle_to_matrix(pose.view(B, NUM_JOINTS, 3))
        return self.lbs(coeffs, rot, t)

    def forward_rotmats(self, rot_mats: Tensor, betas: Tensor | None = None,
                        expression: Tensor | None = None, transl: Tensor | None = None) -> BodyOutput:
        """Forward from rotation matrices (B,55,3,3) of all joints (hand mean NOT added): for networks."""
        if not isinstance(rot_mats, Tensor):
            raise TypeError(f"rot_mats: expected a torch.Tensor, got {type(rot_mats).__name__}")
        if not rot_mats.is_floating_point():
            raise TypeError(f"rot_mats: expected a floating-point tensor, got {rot_mats.dtype}")
        if rot_mats.dim() != 4 or tuple(rot_mats.shape[1:]) != (NUM_JOINTS, 3, 3):
            raise ValueError(f"rot_mats: expected shape (B, 55, 3, 3), got {tuple(rot_mats.shape)}")
        if rot_mats.device != self.v_template.device:
            raise ValueError(f"rot_mats: on {rot_mats.device}, but the model is on {self.v_template.device}")
        named = dict(rot_mats=rot_mats, betas=betas, expression=expression, transl=transl)
        B = self._batch_size(named)
        coeffs = torch.cat([self._coeffs(betas, "betas", self.num_betas, B),
                            self._coeffs(expression, "expression", self.num_expression, B)], dim=1)
        rot = rot_mats.to(self.dtype) if len(rot_mats) == B else rot_mats.to(self.dtype).expand(B, -1, -1, -1)
        t = self._arg(transl, "transl", (3,), B)
        self._check_finite(named, rot, coeffs, t)
        return self.lbs(coeffs, rot, t)

    @staticmethod
    def _check_finite(named: dict[str, Tensor | None], *converted: Tensor) -> None:
        """ValueError naming the arguments with NaN or Inf unless the `converted` inputs are all finite."""
        if all(torch.isfinite(x).all() for x in converted):
            return
        bad = [k for k, v in named.items() if isinstance(v, Tensor) and not torch.isfinite(v).all()]
        if not bad:    # finite as given, but too large for the model's dtype
            raise ValueError(f"inputs: overflow to Inf in {converted[0].dtype}")
        raise ValueError(f"{', '.join(bad)}: contains NaN or Inf")

    def shaped(self, coeffs: Tensor) -> tuple[Tensor, Tensor]:
        """Rest-pose vertices (B,V,3) and joints (B,55,3) for stacked [betas, expression] coeffs (B,S+E)."""
        v, J = self._shaped_cm(coeffs)
        return v.transpose(1, 2), J

    def _shaped_cm(self, coeffs: Tensor) -> tuple[Tensor, Tensor]:
        """Coordinate-major rest vertices (B,3,V) and joints (B,55,3)."""
        B = coeffs.shape[0]
        v = torch.addmm(self._v_template_cm, coeffs, self.shape_basis).view(B, 3, -1)
        J = torch.addmm(self.J_template.view(1, -1), coeffs, self.J_basis).view(B, NUM_JOINTS, 3)
        return v, J

    def lbs(self, coeffs: Tensor, rot: Tensor, transl: Tensor) -> BodyOutput:
        """Blend shapes + skinning: coeffs (B,S+E), rot (B,55,3,3), transl (B,3) -> BodyOutput."""
        B = coeffs.shape[0]
        v, J = self._shaped_cm(coeffs)                                  # (B,3,V), (B,55,3)
        if self.has_posedirs:
            eye = torch.eye(3, dtype=rot.dtype, device=rot.device)
            feat = (rot[:, 1:] - eye).reshape(B, NUM_POSE_BASIS)
            if len(self._pose_rows) < NUM_POSE_BASIS:
                feat = feat[:, self._pose_rows]
            v = torch.addmm(v.view(B, -1), feat, self._posedirs_used).view(B, 3, -1)
        Rg, tg = self.global_transforms(rot, J)                       # (B,55,3,3), (B,55,3)
        # skinning transform of joint k: x -> Rg_k (x - J_k) + tg_k; rows of A: columns of Rg, then the offset
        offset = tg - (Rg @ J.unsqueeze(-1)).squeeze(-1)
        A = torch.cat([Rg.transpose(2, 3), offset.unsqueeze(2)], dim=2)                # (B,55,4,3)
        A = A.reshape(B, NUM_JOINTS, 12).transpose(1, 2)                                # (B,12,55)
        # chunks of bodies: a (B,12,V) product for a large batch leaves the caches (and is a fresh allocation every
        # call); the same per-body arithmetic in chunks of SKIN_CHUNK_BYTES is bit-equal and 1.4-1.7x faster at B = 512
        n = max(1, SKIN_CHUNK_BYTES // (12 * self.num_vertices * v.element_size()))
        verts = self._skin(A, v, transl) if B <= n else \
            torch.cat([self._skin(A[s:s + n], v[s:s + n], transl[s:s + n]) for s in range(0, B, n)])
        return BodyOutput(verts, tg + transl.unsqueeze(1), self.faces, rot)

    def _skin(self, A: Tensor, v: Tensor, transl: Tensor) -> Tensor:
        """Linear blend skinning of n bodies: transforms A (n,12,55), rest vertices (n,3,V), transl (n,3) -> (n,V,3)."""
        n = A.shape[0]
        T = torch.mm(A.reshape(n * 12, NUM_JOINTS), self._weights_t).view(n, 4, 3, -1)    # one GEMM: (n,4,3,V)
        verts = T[:, 3] + T[:, 0] * v[:, 0:1] + T[:, 1] * v[:, 1:2] + T[:, 2] * v[:, 2:3]      # (n,3,V)
        # the translation after the blend, as smplx adds it: inside it, float32 would round it with the weights
        verts = verts + transl.unsqueeze(2)
        return verts.transpose(1, 2).contiguous()

    def global_transforms(self, rot: Tensor, J: Tensor) -> tuple[Tensor, Tensor]:
        """Walk the kinematic tree level by level: local rot (B,55,3,3), rest joints (B,55,3) -> global R, t.

        Each joint's local transform is a 4x4 [rot | J - J_parent]; a level is one gather of its parents' global
        transforms and one batched matmul (about 30 small ops per call instead of one per joint)."""
        B = rot.shape[0]
        rel = J - torch.cat([J.new_zeros(B, 1, 3), J[:, self.parents[1:]]], dim=1)
        local = torch.cat([torch.cat([rot, rel.unsqueeze(-1)], dim=3),
                           torch.cat([rot.new_zeros(B, NUM_JOINTS, 1, 3), rot.new_ones(B, NUM_JOINTS, 1, 1)], dim=3)],
                          dim=2)[:, self._order]                                             # (B,55,4,4), level order
        G = [local[:, :self._spans[0][1]]]
        for (a, b), slot in zip(self._spans[1:], self._parent_slot[1:]):
            G.append(G[-1][:, slot] @ local[:, a:b])
        G = torch.cat(G, 1)[:, self._unorder]
        return G[..., :3, :3], G[..., :3, 3]

    def extra_repr(self) -> str:
        kind = "procedural humanoid" if self.is_procedural else "SMPL-X file"
        return (f"{kind} {self.source}: V={self.num_vertices}, betas={self.num_betas}, "
                f"expression={self.num_expression}, use_pca={self.use_pca}, pose_correctives={self.has_posedirs}")


def shared_body(path: str | os.PathLike | None = None, **kwargs: Any) -> BodyModel:
    """BodyModel.from_file(path, **kwargs) (path default: the file default_model_path() names now), built once per
    version of the file (resolved path, mtime, size) and kwargs, and shared: GRASPKIT_MODEL set later in a process, or
    the file rewritten in place, gives the new body (per-process caches kept the first one). Do not modify it."""
    from graspkit.paths import default_model_path, file_stamp

    return _shared_body(file_stamp(path or default_model_path()), tuple(sorted(kwargs.items())))


@lru_cache(maxsize=4)
def _shared_body(stamp: tuple[str, int, int], kwargs: tuple[tuple[str, Any], ...]) -> BodyModel:
    """shared_body for one file version (a missing file: its reader's error)."""
    return BodyModel.from_file(stamp[0], **dict(kwargs))
