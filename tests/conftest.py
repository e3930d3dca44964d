"""Shared fixtures: one torch thread per test module, the shipped body model, and a random dense SMPL-X-format model
file in a smplx-style folder."""
from pathlib import Path

import numpy as np
import pytest
import torch

from graspkit.body import BodyModel
from graspkit.body.random_model import random_smplx_arrays

ROOT = Path(__file__).resolve().parents[1]
PROCEDURAL_MODEL = ROOT / "data_stubs" / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz"


def jittered_plane(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """An n x n unit grid jittered by up to 0.2 in the plane z = 0 (vertices (n*n, 3)) and scipy's Delaunay
    triangulation of it, counter-clockwise seen from +z (faces (F, 3))."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(float(n)), np.arange(float(n))), -1).reshape(-1, 2)
    p = g + rng.uniform(-0.2, 0.2, g.shape)
    tri = Delaunay(p).simplices
    v = np.column_stack([p, np.zeros(len(p))])
    n_z = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])[:, 2]
    return v, np.where((n_z < 0)[:, None], tri[:, ::-1], tri)


def npz_copy(src: Path, dst: Path, **replace) -> Path:
    """The .npz `src` written to `dst` (compressed) with arrays replaced (a value None drops the key); returns dst."""
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in replace.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez_compressed(dst, **arrays)          # the body model is mostly zeros: 2.6 MB, not 137 MB
    return dst


def relabelled(src: Path, dst: Path, bm) -> Path:
    """The grasp / approach files of folder src copied to dst with GOAL's stored vertices (`goal.vertices`, at the grasp
    frame) recomputed on body model bm: files as if made on bm, their poses unchanged."""
    from graspkit.data.grab import grasp_frame
    from graspkit.data.motion import Motion

    dst.mkdir(parents=True)
    for p in sorted(Path(src).glob("*.npz")):
        with np.load(p, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
        f = grasp_frame(a)
        m = Motion(a["body.params.fullpose"][f:f + 1].reshape(1, 55, 3), a["body.params.transl"][f:f + 1],
                   a["body.betas"], 30.0)
        npz_copy(p, dst / p.name, **{"goal.vertices": m.vertices(bm)[0, a["goal.vertex_ids"]].numpy()})
    return dst


def smplx_posed(model: Path, fullpose: np.ndarray, trans: np.ndarray, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The smplx package's vertices (n, V, 3) and joints (n, J, 3), float64, of the model file `model` (smplx.create's
    layout: <root>/smplx/SMPLX_NEUTRAL.npz) for full poses (n, 165) or (n, 55, 3) (axis-angle, the hand mean not
    added), translations (n, 3) and betas (10,)."""
    import smplx

    n = len(fullpose)
    p = torch.as_tensor(np.asarray(fullpose).reshape(n, 165), dtype=torch.float64)
    ref = smplx.create(str(Path(model).parent.parent), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=n, dtype=torch.float64)
    out = ref(betas=torch.as_tensor(np.asarray(betas)[None, :10], dtype=torch.float64).expand(n, -1),
              global_orient=p[:, :3], body_pose=p[:, 3:66], jaw_pose=p[:, 66:69], leye_pose=p[:, 69:72],
              reye_pose=p[:, 72:75], left_hand_pose=p[:, 75:120], right_hand_pose=p[:, 120:165],
              expression=torch.zeros(n, 10, dtype=torch.float64), transl=torch.as_tensor(trans, dtype=torch.float64))
    return out.vertices.detach().numpy(), out.joints.detach().numpy()


@pytest.fixture(scope="module")
def big(tmp_path_factory) -> Path:
    """graspkit's body 8 % larger, as <tmp>/models/smplx/SMPLX_NEUTRAL.npz (smplx.create's layout)."""
    folder = tmp_path_factory.mktemp("big") / "models" / "smplx"
    folder.mkdir(parents=True)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        return npz_copy(PROCEDURAL_MODEL, folder / "SMPLX_NEUTRAL.npz", v_template=z["v_template"] * 1.08,
                        shapedirs=z["shapedirs"] * 1.08)


@pytest.fixture(scope="session")
def random_model_dir(tmp_path_factory) -> Path:
    """A folder `<tmp>/smplx/SMPLX_NEUTRAL.npz` holding a random dense model (non-zero pose correctives)."""
    root = tmp_path_factory.mktemp("random_body_models")
    (root / "smplx").mkdir()
    np.savez(root / "smplx" / "SMPLX_NEUTRAL.npz", **random_smplx_arrays(seed=7))
    return root


@pytest.fixture(autouse=True)
def bars_as_the_calls_say(monkeypatch):
    """No TQDM_DISABLE from the shell or CI: the tests that check a bar is drawn (or not) set it themselves."""
    monkeypatch.delenv("TQDM_DISABLE", raising=False)


@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """One torch thread in every test module (restored afterwards): the machine's two cores are shared, and the many
    small tensor ops of the tests run several times faster on one thread than on two."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(autouse=True)
def one_thread_each_test(one_thread):
    """Back to one thread after each test: a command a test runs (`--threads 2` by default) left the rest of its module
    on two, so which tests ran on two depended on their order (an independent check)."""
    yield
    torch.set_num_threads(1)


@pytest.fixture(scope="module")
def bm() -> BodyModel:
    """The shipped procedural humanoid (float32, hand mean added), one per test module; a module that needs another
    body model defines its own `bm`."""
    return BodyModel.from_file(PROCEDURAL_MODEL)
