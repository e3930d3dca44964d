"""Whole-sequence exports (graspkit.viz.export_motion): the AMASS-style npz read back by the smplx package and the
GLB files read back by trimesh give the same bodies as graspkit."""
import json
import struct
from pathlib import Path

import numpy as np
import pytest
import smplx
import torch
import trimesh
from matplotlib.colors import to_rgba
from scipy.spatial.transform import Rotation

from graspkit.body import BodyModel
from graspkit.data import load_motion
from graspkit.viz.export import Z_UP_TO_Y_UP, export_motion, export_scene, export_sequence_glb, load_sequence_glb
from graspkit.viz.style import OBJECT, SKIN

from conftest import PROCEDURAL_MODEL

CLIP = sorted((Path(__file__).resolve().parents[1] / "data_stubs" / "motion" / "reach").glob("*.npz"))[0]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    bm = BodyModel.from_file(PROCEDURAL_MODEL, flat_hand_mean=True)
    full = load_motion(CLIP)
    m = full.slice(max(0, full.goal_frame - 20), full.goal_frame + 1)          # the last 21 frames of the reach
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    box.apply_translation(full.goal)
    folder = tmp_path_factory.mktemp("export")
    return m, bm, box, export_motion(m, bm, folder, "reach", objects={"box": box}, stride=5)


def test_npz_in_smplx_gives_graspkit_vertices(exported):
    m, bm, _, paths = exported
    with np.load(paths["npz"], allow_pickle=False) as z:
        poses, trans, betas = (torch.as_tensor(z[k], dtype=torch.float64) for k in ("poses", "trans", "betas"))
    T = len(poses)
    ref = smplx.create(str(PROCEDURAL_MODEL.parents[1]), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
    out = ref(betas=betas[None].expand(T, -1), global_orient=poses[:, :3], body_pose=poses[:, 3:66],
              jaw_pose=poses[:, 66:69], leye_pose=poses[:, 69:72], reye_pose=poses[:, 72:75],
              left_hand_pose=poses[:, 75:120], right_hand_pose=poses[:, 120:165], transl=trans,
              expression=torch.zeros(T, 10, dtype=torch.float64))
    ours = m.vertices(bm).double()
    assert T == m.num_frames and (ours - out.vertices).abs().max() < 1e-4


def test_npz_per_part_keys_pose_the_same_body_in_smplx(exported):
    """A loader that reads AMASS's per-part keys (root_orient, pose_body, pose_jaw, pose_eye, pose_hand) instead of
    `poses` gets the same vertices from smplx as graspkit's own; the keys carry the file's length and shape size."""
    m, bm, _, paths = exported
    with np.load(paths["npz"], allow_pickle=False) as z:
        k = {n: torch.as_tensor(z[n], dtype=torch.float64) for n in
             ("root_orient", "pose_body", "pose_jaw", "pose_eye", "pose_hand", "trans", "betas")}
        assert int(z["num_betas"]) == 10 and abs(float(z["mocap_time_length"]) - m.num_frames / m.fps) < 1e-9
    T = len(k["trans"])
    ref = smplx.create(str(PROCEDURAL_MODEL.parents[1]), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
    out = ref(betas=k["betas"][None].expand(T, -1), global_orient=k["root_orient"], body_pose=k["pose_body"],
              jaw_pose=k["pose_jaw"], leye_pose=k["pose_eye"][:, :3], reye_pose=k["pose_eye"][:, 3:],
              left_hand_pose=k["pose_hand"][:, :45], right_hand_pose=k["pose_hand"][:, 45:], transl=k["trans"],
              expression=torch.zeros(T, 10, dtype=torch.float64))
    assert (m.vertices(bm).double() - out.vertices).abs().max() < 1e-4
    assert load_motion(paths["npz"]).num_frames == m.num_frames          # the reader still takes the file


def test_glb_files_read_back_with_trimesh(exported):
    m, bm, box, paths = exported
    v = m.vertices(bm).numpy()
    frames, faces, times = load_sequence_glb(paths["glb"])
    assert np.array_equal(faces, bm.faces.numpy())
    kept = sorted(set(range(0, m.num_frames, 5)) | {m.num_frames - 1})     # every 5th frame and the last
    assert len(frames) == len(kept) and np.abs(frames - v[kept]).max() < 1e-4
    assert np.allclose(times, np.array(kept) / m.fps)
    scene = trimesh.load(paths["final_glb"])
    geoms = dict(scene.geometry)
    assert set(geoms) == {"body", "box"}
    body = geoms["body"]
    assert len(body.vertices) == v.shape[1]
    assert np.abs(np.asarray(body.vertices) - v[-1] @ Z_UP_TO_Y_UP.T).max() < 1e-4
    assert np.abs(np.asarray(geoms["box"].vertices) - box.vertices @ Z_UP_TO_Y_UP.T).max() < 1e-5
    static = trimesh.load(paths["glb"])                      # a viewer without animation shows frame 0
    assert np.abs(np.asarray(next(iter(static.geometry.values())).vertices) - v[0] @ Z_UP_TO_Y_UP.T).max() < 1e-4


def test_bad_name_is_refused(exported, tmp_path):
    m, bm, box, _ = exported
    with pytest.raises(ValueError, match="name"):
        export_motion(m, bm, tmp_path, "../escape")
    with pytest.raises(ValueError, match="objects: 'body' is the body mesh's name"):   # it replaced the body
        export_motion(m, bm, tmp_path, "x", objects={"body": box})
    assert not list(tmp_path.iterdir())                          # refused before any file
    (tmp_path / "y.glb").mkdir()                                 # it wrote y.npz, then failed on the glb
    with pytest.raises(ValueError, match="y.glb is a folder"):
        export_motion(m, bm, tmp_path, "y")
    assert [p.name for p in tmp_path.iterdir()] == ["y.glb"]


# The animated GLB plays the input frames at their times, and its header follows the glTF 2.0 binary layout (total
# length = file size).
def _accessor(gltf, blob, i):
    acc = gltf["accessors"][i]
    view = gltf["bufferViews"][acc["bufferView"]]
    width = {"SCALAR": 1, "VEC3": 3}[acc["type"]]
    dtype = np.uint32 if acc["componentType"] == 5125 else np.float32
    a = np.frombuffer(blob, dtype, acc["count"] * width, view["byteOffset"] + acc.get("byteOffset", 0))
    return a.reshape(acc["count"], width) if width > 1 else a


def _parse(path):
    """glTF 2.0 binary container, read by the specification (12-byte header, then JSON and BIN chunks)."""
    data = path.read_bytes()
    magic, version, total = struct.unpack_from("<III", data, 0)
    n_json, kind_json = struct.unpack_from("<II", data, 12)
    gltf = json.loads(data[20:20 + n_json])
    n_bin, kind_bin = struct.unpack_from("<II", data, 20 + n_json)
    blob = data[28 + n_json:28 + n_json + n_bin]
    return data, (magic, version, total, kind_json, kind_bin), gltf, blob


def test_glb_animation_shows_each_input_frame_at_its_time_and_the_header_is_the_file_size(tmp_path):
    rng = np.random.default_rng(0)
    T, fps, stride = 7, 20.0, 2
    base = rng.normal(size=(4, 3))
    verts = base + 0.1 * rng.normal(size=(T, 4, 3))            # 7 distinct frames of a tetrahedron
    faces = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]])
    path = export_sequence_glb(verts, faces, tmp_path / "seq.glb", fps=fps, stride=stride, y_up=False)
    data, (magic, version, total, kj, kb), gltf, blob = _parse(path)
    assert (magic, version, kj, kb) == (0x46546C67, 2, 0x4E4F534A, 0x004E4942)
    assert total == len(data)                                  # glTF 2.0: the header's length is the whole file's
    prim = gltf["meshes"][0]["primitives"][0]
    pos = _accessor(gltf, blob, prim["attributes"]["POSITION"])
    targets = np.stack([_accessor(gltf, blob, t["POSITION"]) for t in prim["targets"]])
    sampler = gltf["animations"][0]["samplers"][0]
    times = _accessor(gltf, blob, sampler["input"])
    weights = _accessor(gltf, blob, sampler["output"]).reshape(len(times), len(targets))
    kept = [0, 2, 4, 6]
    assert np.allclose(times, np.array(kept) / fps)
    for key, k in enumerate(kept):                             # what a viewer draws at the key's time
        shown = pos + np.tensordot(weights[key], targets, 1)
        assert np.abs(shown - verts[k]).max() < 1e-5, k


def _tet(shift=(0.0, 0.0, 0.0)):
    """A tetrahedron (vertices (4,3), outward faces (4,3)) moved by shift."""
    v = np.array([[1.0, 2.0, 3.0], [1.5, 2.0, 3.0], [1.0, 2.5, 3.0], [1.0, 2.0, 3.5]]) + np.asarray(shift)
    return v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_glb_scene_is_y_up_by_a_rotation(tmp_path):
    """glTF is y-up and right-handed: a z-up point (x, y, z) is (x, z, -y) in the file (a -90 deg turn about x, det
    +1, so that a mesh's winding and handedness survive), read back with trimesh."""
    v, f = _tet()
    path = export_scene({"tet": (v, f)}, tmp_path / "t.glb")
    got = np.asarray(next(iter(trimesh.load(path).geometry.values())).vertices)
    want = np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1)
    assert np.abs(got - want).max() < 1e-6


def test_glb_sequence_first_frame_is_y_up_by_a_rotation(tmp_path):
    """The animated GLB's base mesh (what a viewer without animation shows) is frame 0 in glTF's y-up frame:
    (x, y, z) -> (x, z, -y), read back with trimesh."""
    v, f = _tet()
    frames = np.stack([v, v + [0.1, 0.0, 0.0]])
    path = export_sequence_glb(frames, f, tmp_path / "s.glb")
    got = np.asarray(next(iter(trimesh.load(path).geometry.values())).vertices)
    assert np.abs(got - np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1)).max() < 1e-6


def _yup(v):
    """glTF's y-up frame by the spec's convention as the module doc states: (x, y, z) -> (x, z, -y) (scipy rotation)."""
    return Rotation.from_euler("x", -90, degrees=True).apply(v)


def _close_rgba(got, want):
    """Colour bytes are the nearest 8-bit value of the wanted colour (within half a step)."""
    got = np.asarray(got, float)
    if got.max() > 1.0:
        got = got / 255.0
    return np.abs(got - np.asarray(want)).max() <= 0.5 / 255 + 1e-9


def test_scene_glb_default_and_given_colours_read_back_by_trimesh(tmp_path):
    """export_scene's colours, read back by trimesh: the first entry skin, the second the object colour (module rule),
    a given colour quantised to the nearest 8-bit value (0.999 -> 255, 0.5 -> 128 not 127)."""
    want3 = (0.999, 0.5, 0.0041, 1.0)
    meshes = {"person": _tet(), "thing": _tet((1, 0, 0)), "third": _tet((2, 0, 0))}
    path = export_scene(meshes, tmp_path / "c.glb", colors={"third": want3})
    scene = trimesh.load_scene(path, process=False)
    col = {n: g.visual.material.baseColorFactor for n, g in scene.geometry.items()}
    assert _close_rgba(col["person"], to_rgba(SKIN))
    assert _close_rgba(col["thing"], to_rgba(OBJECT))
    assert _close_rgba(col["third"], want3)
    ply = trimesh.load(export_scene({"a": _tet()}, tmp_path / "c.ply", colors={"a": want3}), process=False)
    assert _close_rgba(ply.visual.vertex_colors[0], want3)


def test_scene_y_up_flag_is_honoured_for_every_format(tmp_path):
    """y_up=True turns an .obj by (x, y, z) -> (x, z, -y) (scipy's -90 deg about x); y_up=False writes a .glb in world
    coordinates: bounds read back by trimesh."""
    v, f = _tet()
    obj = trimesh.load_scene(export_scene({"t": (v, f)}, tmp_path / "t.obj", y_up=True), process=False)
    np.testing.assert_allclose(obj.bounds, [_yup(v).min(0), _yup(v).max(0)], atol=1e-6)
    glb = trimesh.load_scene(export_scene({"t": (v, f)}, tmp_path / "t.glb", y_up=False), process=False)
    np.testing.assert_allclose(np.asarray(glb.geometry["t"].vertices), v, atol=1e-6)


def test_export_scene_refuses_nan_vertices(tmp_path):
    """A NaN vertex is refused with a ValueError naming the mesh (no file written), as for sequences."""
    v, f = _tet()
    v[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        export_scene({"bad": (v, f)}, tmp_path / "n.glb")
    assert list(tmp_path.iterdir()) == []


def test_sequence_glb_refuses_bool_stride_and_out_of_range_faces(tmp_path):
    """stride must be an integer >= 1 (True is a flag, 0 is no step) and face indices must lie in [0, V): a vertex
    index V or -1 names no vertex, so the file would be broken."""
    v, f = _tet()
    frames = np.stack([v, v + 0.1])
    with pytest.raises(TypeError, match="stride"):
        export_sequence_glb(frames, f, tmp_path / "a.glb", stride=True)
    with pytest.raises(ValueError, match="stride"):
        export_sequence_glb(frames, f, tmp_path / "b.glb", stride=0)
    for bad in (4, -1):
        g = f.copy()
        g[2, 1] = bad
        with pytest.raises(ValueError, match="faces"):
            export_sequence_glb(frames, g, tmp_path / "c.glb")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("oname", ["o", "oo", "ooo", "oooo"])
def test_sequence_glb_follows_the_gltf_binary_spec(tmp_path, oname):
    """glTF 2.0: the JSON chunk is padded with spaces to 4 bytes; POSITION accessors (base and morph targets) and
    animation inputs carry per-component min/max equal to their data; index views target ELEMENT_ARRAY_BUFFER
    (34963), vertex views ARRAY_BUFFER (34962); primitives are TRIANGLES (mode 4); the clip is LINEAR as documented."""
    rng = np.random.default_rng(1)
    v, f = _tet()
    frames = v + 0.05 * rng.normal(size=(5, 4, 3))
    path = export_sequence_glb(frames, f, tmp_path / "s.glb", fps=10, objects={oname: _tet((0, 1, 0))})
    data, _, gltf, blob = _parse(path)
    js = data[20:20 + struct.unpack_from("<I", data, 12)[0]]
    assert len(js) % 4 == 0 and (len(data) - len(blob)) % 4 == 0
    assert js.rstrip(b" ").endswith(b"}")                                     # the padding is spaces only
    views = gltf["bufferViews"]
    for mesh in gltf["meshes"]:
        for prim in mesh["primitives"]:
            assert prim.get("mode", 4) == 4
            assert views[gltf["accessors"][prim["indices"]]["bufferView"]].get("target") == 34963
            pos = [prim["attributes"]["POSITION"]] + [t["POSITION"] for t in prim.get("targets", [])]
            for i in pos:
                a = _accessor(gltf, blob, i)
                acc = gltf["accessors"][i]
                assert views[acc["bufferView"]].get("target") == 34962
                assert len(acc["min"]) == len(acc["max"]) == 3
                np.testing.assert_allclose(acc["min"], a.min(0), atol=1e-6)
                np.testing.assert_allclose(acc["max"], a.max(0), atol=1e-6)
    s = gltf["animations"][0]["samplers"][0]
    t = _accessor(gltf, blob, s["input"])
    assert s["interpolation"] == "LINEAR"
    assert gltf["accessors"][s["input"]]["min"] == [t.min()] and gltf["accessors"][s["input"]]["max"] == [t.max()]


def test_sequence_glb_static_objects_are_turned_y_up_and_coloured(tmp_path):
    """The static objects of an animated GLB are in glTF's y-up frame like the body (scipy rotation), read back by
    trimesh; an object without a colour gets the object colour, a given colour is used, the body is opaque skin."""
    v, f = _tet()
    cup, plate = _tet((0.3, 0, 0)), _tet((0, 0.4, 0))
    path = export_sequence_glb(np.stack([v, v + 0.1]), f, tmp_path / "o.glb", objects={"cup": cup, "plate": plate},
                               colors={"plate": "tab:green"})
    scene = trimesh.load_scene(path, process=False)
    np.testing.assert_allclose(np.asarray(scene.geometry["cup"].vertices), _yup(cup[0]), atol=1e-6)
    np.testing.assert_allclose(np.asarray(scene.geometry["plate"].vertices), _yup(plate[0]), atol=1e-6)
    col = {n: g.visual.material.baseColorFactor for n, g in scene.geometry.items()}
    assert _close_rgba(col["cup"], to_rgba(OBJECT))
    assert _close_rgba(col["plate"], to_rgba("tab:green"))
    assert _close_rgba(col["body"], to_rgba(SKIN))


def test_writers_refuse_a_file_name_of_another_format(tmp_path):
    """export_sequence_glb wrote binary GLB into seq.gltf (JSON text by the glTF specification: trimesh and
    `graspkit goal --object` could not read it back), save_png PNG bytes into fig.jpg, save_motion an npz into
    clip.json; each now refuses, naming `path`, and writes nothing."""
    import matplotlib.pyplot as plt

    from graspkit.data.formats import save_motion
    from graspkit.data.motion import Motion
    from graspkit.viz.export import export_sequence_glb, save_png

    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]] * 2)
    for name in ("seq.gltf", "seq.png", "seq"):
        with pytest.raises(ValueError, match=r"^path: expected a file ending in \.glb"):
            export_sequence_glb(tri, [[0, 1, 2]], tmp_path / name)
    assert export_sequence_glb(tri, [[0, 1, 2]], tmp_path / "seq.GLB").read_bytes()[:4] == b"glTF"
    with pytest.raises(ValueError, match=r"^path: expected a file ending in \.png"):
        save_png(plt.figure(figsize=(1, 1)), tmp_path / "fig.jpg")
    m = Motion(np.zeros((2, 55, 3)), np.zeros((2, 3)), np.zeros(10), 30.0)
    with pytest.raises(ValueError, match=r"^path: expected a file ending in \.npz"):
        save_motion(tmp_path / "clip.json", m)
    from graspkit.data.grab import load_grasp_sequence, save_grasp_sequence
    from graspkit.data.motionfill_dataset import save_windows
    from graspkit.paths import DATA_STUBS
    from graspkit.train import write_history_csv, write_history_plot

    seq = load_grasp_sequence(DATA_STUBS / "grasps" / "grasp_000000.npz")
    for write, name, suffix in ((lambda p: save_grasp_sequence(p, seq), "s.json", ".npz"),
                                (lambda p: save_windows(p, {"a": np.zeros(2)}), "w.pt", ".npz"),
                                (lambda p: write_history_csv(p, [{"epoch": 1, "loss": 1.0}]), "h.png", ".csv"),
                                (lambda p: write_history_plot(p, [{"epoch": 1, "loss": 1.0}]), "h.csv", ".png")):
        with pytest.raises(ValueError, match=rf"^path: expected a file ending in {suffix} "):
            write(tmp_path / name)
    plt.close("all")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq.GLB"]
