"""BodyModel against the smplx package (parity), analytic cases, gradients and input/file validation."""
import pickle

import numpy as np
import pytest
import smplx
import smplx.joint_names as SJ
import smplx.vertex_ids as SV
import torch
from scipy.spatial.transform import Rotation

from graspkit.body import BodyModel, ModelFileError
from graspkit.body.poses import POSES, body_pose, y_up_to_z_up
from graspkit.body.random_model import random_smplx_arrays
from graspkit.body.skeleton import FINGERS, JOINT_INDEX, JOINT_NAMES, PARENTS, SMPLX_LANDMARK_VERTEX_IDS
from graspkit.rotations import axis_angle_to_matrix


def _params(B: int, n_hand: int, dtype, seed: int = 0) -> dict:
    """Random SMPL-X parameters of a batch, every argument given (smplx needs them all at batch B)."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *s, k=1.0: (torch.randn(*s, generator=g, dtype=torch.float64) * k).to(dtype)  # noqa: E731
    return dict(betas=r(B, 10), expression=r(B, 10), global_orient=r(B, 3), body_pose=r(B, 63, k=0.5),
                left_hand_pose=r(B, n_hand, k=0.5), right_hand_pose=r(B, n_hand, k=0.5), jaw_pose=r(B, 3, k=0.3),
                leye_pose=r(B, 3, k=0.3), reye_pose=r(B, 3, k=0.3), transl=r(B, 3))


def _parity(model_dir, use_pca: bool, flat: bool, dtype) -> tuple[float, float]:
    """Max vertex and joint deviation (m) between graspkit and smplx on one file and random parameters."""
    kw = dict(use_pca=use_pca, num_pca_comps=12, flat_hand_mean=flat, dtype=dtype)
    ref = smplx.create(str(model_dir), model_type="smplx", gender="neutral", ext="npz", **kw)
    ours = BodyModel.from_file(model_dir / "smplx" / "SMPLX_NEUTRAL.npz", **kw)
    p = _params(4, 12 if use_pca else 45, dtype)
    with torch.no_grad():
        a, b = ref(**p), ours(**p)
    return (a.vertices - b.vertices).abs().max().item(), (a.joints[:, :55] - b.joints).abs().max().item()


@pytest.mark.parametrize("use_pca", [False, True])
@pytest.mark.parametrize("flat", [False, True])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_parity_with_smplx_on_dense_random_model(random_model_dir, use_pca, flat, dtype):
    dv, dj = _parity(random_model_dir, use_pca, flat, dtype)
    assert dv <= 1e-5 and dj <= 1e-5, (dv, dj)


@pytest.mark.parametrize("use_pca", [False, True])
def test_parity_with_smplx_on_the_shipped_procedural_file(use_pca):
    from graspkit.paths import default_model_path

    dv, dj = _parity(default_model_path().parents[1], use_pca, False, torch.float32)
    assert dv <= 1e-5 and dj <= 1e-5, (dv, dj)


def test_zero_parameters_give_the_template_and_regressed_joints():
    arr = random_smplx_arrays(num_vertices=300, num_faces=100, seed=1)
    out = BodyModel(arr, flat_hand_mean=True, dtype=torch.float64)()
    assert out.vertices.shape == (1, 300, 3) and out.joints.shape == (1, 55, 3)
    np.testing.assert_allclose(out.vertices[0].numpy(), arr["v_template"], atol=1e-12)
    np.testing.assert_allclose(out.joints[0].numpy(), arr["J_regressor"] @ arr["v_template"], atol=1e-12)


def test_global_orient_rotates_the_body_about_the_root_joint():
    arr = random_smplx_arrays(num_vertices=300, num_faces=100, seed=2)
    bm = BodyModel(arr, dtype=torch.float64)
    betas = torch.randn(1, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    aa = torch.tensor([[0.3, -1.2, 2.0]], dtype=torch.float64)
    rest, turned = bm(betas=betas), bm(betas=betas, global_orient=aa)
    R, root = axis_angle_to_matrix(aa)[0], rest.joints[0, 0]
    expect = (rest.vertices[0] - root) @ R.T + root
    np.testing.assert_allclose(turned.vertices[0].numpy(), expect.numpy(), atol=1e-12)


def test_transl_and_batch_broadcast():
    bm = BodyModel(random_smplx_arrays(num_vertices=200, num_faces=50, seed=3), dtype=torch.float64)
    pose = torch.randn(3, 63, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    t = torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64)
    a, b = bm(body_pose=pose), bm(body_pose=pose, transl=t)  # transl of batch 1 broadcasts to 3
    np.testing.assert_allclose((b.vertices - a.vertices).numpy(), np.broadcast_to([1.0, 2.0, 3.0], (3, 200, 3)))
    np.testing.assert_allclose((b.joints - a.joints).numpy(), np.broadcast_to([1.0, 2.0, 3.0], (3, 55, 3)))


def test_float32_translation_far_from_the_origin_matches_smplx():
    """smplx adds transl after skinning; inside the float32 weight blend it would round with the weights (2e-5 m at
    100 m before the fix; float32 itself spaces numbers 7.6e-6 apart there)."""
    from graspkit.paths import default_model_path

    kw = dict(use_pca=False, flat_hand_mean=False, dtype=torch.float32)
    ref = smplx.create(str(default_model_path().parents[1]), model_type="smplx", gender="neutral", ext="npz", **kw)
    ours = BodyModel.from_file(default_model_path(), **kw)
    p = _params(2, 45, torch.float32, seed=5)
    p["transl"] = torch.tensor([[100.0, -100.0, 100.0], [-70.0, 25.0, 3.0]])     # float32 spacing at 100: 7.6e-6
    with torch.no_grad():
        a, b = ref(**p), ours(**p)
    assert (a.vertices - b.vertices).abs().max().item() <= 1e-5
    assert (a.joints[:, :55] - b.joints).abs().max().item() <= 1e-5


def test_gradcheck_through_pose_and_shape():
    bm = BodyModel(random_smplx_arrays(num_vertices=40, num_faces=20, seed=4), dtype=torch.float64)
    g = torch.Generator().manual_seed(1)
    pose = (torch.randn(2, 63, dtype=torch.float64, generator=g) * 0.5).requires_grad_(True)
    betas = torch.randn(2, 10, dtype=torch.float64, generator=g).requires_grad_(True)
    f = lambda p, b: bm(body_pose=p, betas=b).vertices  # noqa: E731
    assert torch.autograd.gradcheck(f, (pose, betas))


def test_a_batch_skinned_in_chunks_matches_smplx_and_the_whole_batch(random_model_dir, monkeypatch):
    import graspkit.body.model as body_model

    ref = smplx.create(str(random_model_dir), model_type="smplx", gender="neutral", ext="npz", use_pca=False)
    ours = BodyModel.from_file(random_model_dir / "smplx" / "SMPLX_NEUTRAL.npz")
    p = _params(8, 45, torch.float32, seed=3)
    with torch.no_grad():
        whole = ours(**p)
        monkeypatch.setattr(body_model, "SKIN_CHUNK_BYTES", 3 * 12 * ours.num_vertices * 4)   # chunks of 3, 3, 2
        chunked, theirs = ours(**p), ref(**p)
    assert (chunked.vertices - theirs.vertices).abs().max() <= 1e-5
    assert torch.allclose(chunked.vertices, whole.vertices, rtol=0, atol=1e-6)
    assert torch.equal(chunked.joints, whole.joints)
    # gradients flow through the chunks: one body a chunk, float64
    bm = BodyModel(random_smplx_arrays(num_vertices=40, num_faces=20, seed=4), dtype=torch.float64)
    monkeypatch.setattr(body_model, "SKIN_CHUNK_BYTES", 1)
    g = torch.Generator().manual_seed(2)
    pose = (torch.randn(3, 63, dtype=torch.float64, generator=g) * 0.5).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: bm(body_pose=x, transl=x[:, :3]).vertices, (pose,))


def test_forward_rotmats_matches_axis_angle_forward():
    bm = BodyModel(random_smplx_arrays(num_vertices=200, num_faces=50, seed=5), dtype=torch.float64, flat_hand_mean=True)
    p = _params(2, 45, torch.float64, seed=2)
    full = torch.cat([p["global_orient"], p["body_pose"], p["jaw_pose"], p["leye_pose"], p["reye_pose"],
                      p["left_hand_pose"], p["right_hand_pose"]], 1).view(2, 55, 3)
    a = bm(**p)
    b = bm.forward_rotmats(axis_angle_to_matrix(full), betas=p["betas"], expression=p["expression"], transl=p["transl"])
    np.testing.assert_allclose(a.vertices.numpy(), b.vertices.numpy(), atol=1e-12)


@pytest.mark.parametrize("kwargs, name", [
    (dict(body_pose=torch.zeros(1, 60)), "body_pose"),
    (dict(betas=torch.zeros(1, 11)), "betas"),
    (dict(left_hand_pose=torch.zeros(1, 6)), "left_hand_pose"),
    (dict(transl=torch.zeros(3)), "transl"),
    (dict(jaw_pose=torch.tensor([[0.0, float("nan"), 0.0]])), "jaw_pose"),
    (dict(body_pose=torch.zeros(2, 63), transl=torch.zeros(3, 3)), "batch sizes"),
    (dict(global_orient=torch.zeros(3), body_pose=torch.zeros(63)),
     r"global_orient: expected a batch .*global_orient\[None\]"),
    (dict(body_pose=torch.zeros(0, 63)), r"body_pose: expected a batch of at least one body"),
])
def test_bad_arguments_name_the_argument(kwargs, name):
    bm = BodyModel(random_smplx_arrays(num_vertices=50, num_faces=20, seed=6))
    with pytest.raises(ValueError, match=name):
        bm(**kwargs)


@pytest.mark.parametrize("dtype", [torch.bool, torch.int64, torch.complex64])
def test_non_float_arguments_are_refused_by_name(dtype):
    """Integer, boolean or complex tensors are refused (they used to be cast, complex ones losing their imaginary part)."""
    bm = BodyModel(random_smplx_arrays(num_vertices=50, num_faces=20, seed=6))
    with pytest.raises(TypeError, match=f"body_pose: expected a floating-point tensor, got {dtype}"):
        bm(body_pose=torch.zeros(1, 63, dtype=dtype))
    with pytest.raises(TypeError, match="betas: expected a floating-point"):
        bm(betas=torch.zeros(1, 10, dtype=dtype))
    with pytest.raises(TypeError, match="rot_mats: expected a floating-point"):
        bm.forward_rotmats(torch.zeros(1, 55, 3, 3, dtype=dtype))


def test_one_joint_arguments_as_b_1_3_match_smplx(random_model_dir):
    """global_orient / jaw / eyes / transl given as (B, 1, 3), as smplx accepts them, pose the same body."""
    p = _params(3, 45, torch.float64)
    kw = dict(use_pca=False, flat_hand_mean=True, dtype=torch.float64)
    ref = smplx.create(str(random_model_dir), model_type="smplx", gender="neutral", ext="npz", **kw)
    ours = BodyModel.from_file(random_model_dir / "smplx" / "SMPLX_NEUTRAL.npz", **kw)
    q = {k: (v[:, None] if k in ("global_orient", "jaw_pose", "leye_pose", "reye_pose") else v) for k, v in p.items()}
    with torch.no_grad():
        assert (ours(**q).vertices - ref(**q).vertices).abs().max() < 1e-7
        assert torch.equal(ours(**q).vertices, ours(**p).vertices)


def test_pca_hand_pose_expects_num_pca_comps():
    bm = BodyModel(random_smplx_arrays(num_vertices=50, num_faces=20, seed=6), use_pca=True, num_pca_comps=6)
    assert bm(left_hand_pose=torch.zeros(2, 6)).vertices.shape == (2, 50, 3)
    with pytest.raises(ValueError, match=r"left_hand_pose: expected shape \(B, 6\)"):
        bm(left_hand_pose=torch.zeros(2, 45))


def test_a_path_given_to_the_constructor_points_to_from_file(tmp_path):
    with pytest.raises(TypeError, match=r"arrays: expected a mapping .* got PosixPath; .* BodyModel.from_file"):
        BodyModel(tmp_path / "model.npz")
    with pytest.raises(TypeError, match=r"arrays: expected a mapping .* got list$"):
        BodyModel([1, 2])


def test_file_errors_name_file_and_key(tmp_path):
    arr = random_smplx_arrays(num_vertices=50, num_faces=20, seed=8)
    missing = {k: v for k, v in arr.items() if k != "weights"}
    np.savez(tmp_path / "missing.npz", **missing)
    with pytest.raises(ModelFileError, match=r"missing.npz: missing key 'weights'"):
        BodyModel.from_file(tmp_path / "missing.npz")
    wrong = dict(arr, J_regressor=arr["J_regressor"][:54])
    np.savez(tmp_path / "wrong.npz", **wrong)
    with pytest.raises(ModelFileError, match=r"wrong.npz: key 'J_regressor' has shape \(54, 50\), expected \(55, 50\)"):
        BodyModel.from_file(tmp_path / "wrong.npz")
    np.savez(tmp_path / "doubled.npz", **dict(arr, weights=2 * arr["weights"]))
    with pytest.raises(ModelFileError, match=r"doubled.npz: key 'weights' row \d+ sums to 2.0000"):
        BodyModel.from_file(tmp_path / "doubled.npz")
    with open(tmp_path / "model.pkl", "wb") as fh:
        pickle.dump(arr, fh)
    with pytest.raises(ModelFileError, match="model.pkl.*pickle"):
        BodyModel.from_file(tmp_path / "model.pkl")
    obj = dict(arr, weights=np.array([None], dtype=object))
    np.savez(tmp_path / "obj.npz", **obj)
    with pytest.raises(ModelFileError, match=r"obj.npz: key 'weights'"):
        BodyModel.from_file(tmp_path / "obj.npz")
    with pytest.raises(ModelFileError, match="no such body-model file"):
        BodyModel.from_file(tmp_path / "nope.npz")
    with pytest.raises(ModelFileError, match=r"is a directory.*missing.npz"):
        BodyModel.from_file(tmp_path)


def test_pickled_model_is_read_only_behind_the_opt_in(tmp_path):
    """An official-style .pkl (latin1 pickle, sparse regressor) loads with allow_pickle=True to the same body."""
    import scipy.sparse

    arr = random_smplx_arrays(num_vertices=50, num_faces=20, seed=9)
    with open(tmp_path / "SMPLX_NEUTRAL.pkl", "wb") as fh:
        pickle.dump(dict(arr, J_regressor=scipy.sparse.csc_matrix(arr["J_regressor"])), fh, protocol=2)
    np.savez(tmp_path / "SMPLX_NEUTRAL.npz", **arr)
    with pytest.raises(ModelFileError, match="SMPLX_NEUTRAL.pkl.*allow_pickle=True"):
        BodyModel.from_file(tmp_path / "SMPLX_NEUTRAL.pkl")
    pose = torch.randn(3, 63, generator=torch.Generator().manual_seed(0)) * 0.3
    a = BodyModel.from_file(tmp_path / "SMPLX_NEUTRAL.pkl", allow_pickle=True)(body_pose=pose)
    b = BodyModel.from_file(tmp_path / "SMPLX_NEUTRAL.npz")(body_pose=pose)
    torch.testing.assert_close(a.vertices, b.vertices, rtol=0, atol=0)
    torch.testing.assert_close(a.joints, b.joints, rtol=0, atol=0)
    with open(tmp_path / "list.pkl", "wb") as fh:
        pickle.dump([1, 2], fh)
    with pytest.raises(ModelFileError, match="list.pkl: expected a pickled dict"):
        BodyModel.from_file(tmp_path / "list.pkl", allow_pickle=True)


def test_digest_names_the_model_arrays_and_dtype():
    """Two loads of one file share a digest; one changed template vertex, another body or another dtype do not."""
    arrays = random_smplx_arrays(num_vertices=300, num_faces=500, seed=3)
    a, b = BodyModel(arrays), BodyModel(dict(arrays))
    assert a.digest() == b.digest() and len(a.digest()) == 12
    moved = dict(arrays, v_template=arrays["v_template"].copy())
    moved["v_template"][7, 2] += 1e-6
    assert BodyModel(moved).digest() != a.digest()
    assert BodyModel(random_smplx_arrays(num_vertices=300, num_faces=500, seed=4)).digest() != a.digest()
    assert BodyModel(arrays, dtype=torch.float64).digest() != a.digest()


def test_digest_is_the_same_whatever_the_thread_count():
    """The shipped body's digest (the key of window and clip caches and the body in `data make`'s folder records) in
    processes of one and of two BLAS / OpenMP threads. Until 2026-12-07 J_template was a threaded BLAS product whose
    last bits depended on the thread count: the same file had two digests, and a folder made in one environment was
    "another body model" in the other."""
    import os
    import subprocess
    import sys

    from graspkit.paths import procedural_model_path

    code = ("import torch; from graspkit.body import BodyModel; "
            f"print(torch.get_num_threads(), BodyModel.from_file({str(procedural_model_path())!r}).digest())")
    out = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          env={**os.environ, "OMP_NUM_THREADS": n, "OPENBLAS_NUM_THREADS": n, "MKL_NUM_THREADS": n}
                          ).stdout.split() for n in ("1", "2")]
    assert [o[0] for o in out] == ["1", "2"] and out[0][1] == out[1][1]


def test_a_400_component_file_matches_smplx_with_16_betas_and_short_betas_pad_at_the_end(tmp_path):
    """In an SMPL-X 2020 file (300 shape + 100 expression components) the expression basis starts at component 300
    whatever num_betas (smplx reads it so); betas shorter than num_betas are the leading components (zero-padded at
    the end). Truth: the smplx package on the same file."""
    arr = random_smplx_arrays(seed=3)
    arr["shapedirs"] = np.random.default_rng(5).normal(scale=0.01, size=arr["shapedirs"].shape[:2] + (400,))
    (tmp_path / "smplx").mkdir()
    np.savez(tmp_path / "smplx" / "SMPLX_NEUTRAL.npz", **arr)
    kw = dict(num_betas=16, num_expression_coeffs=10, use_pca=False, flat_hand_mean=True, dtype=torch.float64)
    ref = smplx.create(str(tmp_path), model_type="smplx", gender="neutral", ext="npz", **kw)
    ours = BodyModel(arr, num_betas=16, num_expression=10, flat_hand_mean=True, dtype=torch.float64)
    p = _params(2, 45, torch.float64)                      # smplx needs every argument at the batch size
    p["betas"] = torch.randn(2, 16, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    with torch.no_grad():
        a, b = ref(**p), ours(**p)
        short = ours(**{**p, "betas": p["betas"][:, :3]}).vertices
        padded = ref(**{**p, "betas": torch.cat([p["betas"][:, :3], torch.zeros(2, 13, dtype=torch.float64)], 1)})
    assert (a.vertices - b.vertices).abs().max().item() < 1e-6            # 1e-7 m as the other parity tests
    assert (short - padded.vertices).abs().max().item() < 1e-6


def test_joint_names_and_finger_order_are_smplx():
    assert list(JOINT_NAMES) == SJ.JOINT_NAMES[:55]
    order = []
    for n in SJ.JOINT_NAMES[25:40]:                      # the left hand's 15 joints in SMPL-X order
        f = n[len("left_"):-1]
        if f not in order:
            order.append(f)
    assert tuple(order) == FINGERS


def test_landmark_vertex_ids_are_smplx_vertex_ids():
    assert SMPLX_LANDMARK_VERTEX_IDS == SV.vertex_ids["smplx"]


def test_finger_jaw_and_eye_parents_follow_the_anatomy():
    for side in ("left", "right"):
        for f in ("index", "middle", "pinky", "ring", "thumb"):
            chain = [f"{side}_wrist", f"{side}_{f}1", f"{side}_{f}2", f"{side}_{f}3"]
            for parent, child in zip(chain[:-1], chain[1:]):
                assert PARENTS[JOINT_INDEX[child]] == JOINT_INDEX[parent], child
    for n in ("jaw", "left_eye_smplhf", "right_eye_smplhf"):
        assert PARENTS[JOINT_INDEX[n]] == JOINT_INDEX["head"], n
    assert PARENTS[JOINT_INDEX["head"]] == JOINT_INDEX["neck"]


def test_body_pose_is_smplx_layout_joints_1_to_21():
    for name, joints in POSES.items():
        bp = body_pose(name, torch.float64)
        assert bp.shape == (1, 63)
        want = np.zeros((21, 3))
        for j, aa in joints.items():
            want[JOINT_INDEX[j] - 1] = aa
        np.testing.assert_array_equal(bp.reshape(21, 3).numpy(), want)


def test_a_pose_lowers_both_arms_symmetrically(bm):
    with torch.no_grad():
        J = bm(body_pose=body_pose("a_pose", bm.dtype)).joints[0].double().numpy()
    for side in ("left", "right"):
        sh, wr = J[JOINT_INDEX[f"{side}_shoulder"]], J[JOINT_INDEX[f"{side}_wrist"]]
        assert wr[1] < sh[1] - 0.2, side                      # y up: the wrist well below the shoulder
    l, r = J[JOINT_INDEX["left_wrist"]], J[JOINT_INDEX["right_wrist"]]
    np.testing.assert_allclose([l[0], l[1]], [-r[0], r[1]], atol=0.02)   # mirror images across x = 0


def test_y_up_to_z_up_maps_canonical_up_to_world_up_and_faces_minus_y():
    R = Rotation.from_rotvec(y_up_to_z_up(torch.float64).numpy()[0]).as_matrix()
    np.testing.assert_allclose(R @ [0, 1, 0], [0, 0, 1], atol=1e-12)      # canonical y up -> world z up
    np.testing.assert_allclose(R @ [0, 0, 1], [0, -1, 0], atol=1e-12)     # facing +z -> facing -y
