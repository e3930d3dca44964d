"""graspkit.viz: figures, colour mapping, shape errors, animations (GIF / HTML) and mesh export round trips."""
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
import trimesh  # noqa: E402
from matplotlib.animation import FuncAnimation  # noqa: E402
from mpl_toolkits.mplot3d import Axes3D  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection  # noqa: E402
from PIL import Image  # noqa: E402

from graspkit import viz  # noqa: E402
from graspkit.viz import animate as animate_fn  # noqa: E402
from graspkit.viz.animate import save_animation, to_html  # noqa: E402
from graspkit.viz.scene import show_scene, sphere  # noqa: E402
from graspkit.viz.export import (Z_UP_TO_Y_UP, export_scene, export_sequence_glb, load_sequence_glb,  # noqa: E402
                                  read_glb)

from test_exports import _tet  # noqa: E402


@pytest.fixture
def body() -> trimesh.Trimesh:
    """A standing capsule 1.7 m tall on the ground (z up), as a stand-in body."""
    return trimesh.creation.capsule(height=1.3, radius=0.2, count=[12, 12]).apply_translation([0, 0, 0.85])


@pytest.fixture
def ball() -> trimesh.Trimesh:
    """A small icosphere object in front of the body."""
    return trimesh.creation.icosphere(1, radius=0.1).apply_translation([0.4, -0.5, 1.0])


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def moving(body: trimesh.Trimesh, T: int) -> np.ndarray:
    """(T, V, 3) frames of body walking along x (every frame differs, so GIF encoders keep them all)."""
    return np.stack([body.vertices + [0.05 * t, 0.0, 0.02 * np.sin(t)] for t in range(T)])


# ---- figures ----

def test_figure_views_and_equal_aspect(body):
    fig, axes = viz.figure(views=("front", "side", "top", (30, 45)), size=2)
    assert len(axes) == 4 and all(isinstance(a, Axes3D) for a in axes)
    assert len([a for a in fig.axes if isinstance(a, Axes3D)]) == 4
    assert (axes[0].elev, axes[0].azim) == viz.VIEWS["front"] and (axes[3].elev, axes[3].azim) == (30, 45)
    pts = np.array([[0, 0, 0], [2.0, 0.5, 1.0]])
    lim = viz.set_equal(axes[1], pts, pad=0.0)
    ranges = lim[1] - lim[0]
    np.testing.assert_allclose(ranges, [2.0, 0.5, 1.0])
    np.testing.assert_allclose([axes[1].get_xlim()[1], axes[1].get_ylim()[1], axes[1].get_zlim()[1]], [2.0, 0.5, 1.0])
    aspect = np.asarray(axes[1].get_box_aspect())
    np.testing.assert_allclose(aspect / aspect[0], ranges / ranges[0], rtol=1e-6)  # one metre is as long on every axis


def test_set_equal_accepts_batches_and_flat_sets():
    ax = viz.figure(views=("iso",))[1][0]
    lim = viz.set_equal(ax, torch.zeros(4, 5, 3), [[1.0, 2.0, 0.0]], pad=0.0)
    assert np.all(lim[1] - lim[0] > 0)  # a flat set still gets a non-degenerate box
    np.testing.assert_allclose(lim[1, :2] - lim[0, :2], [1.0, 2.0], rtol=0.1)


def test_draw_mesh_lit_and_torch_input(body):
    fig, (ax,) = viz.figure(views=("front",))
    v = torch.tensor(body.vertices, requires_grad=True)
    pc = viz.draw_mesh(ax, v * 1.0, torch.tensor(body.faces))
    colors = np.asarray(pc.get_facecolor())        # a tuple of RGBA rows in matplotlib 3.7
    assert len(colors) == len(body.faces)
    assert colors[:, :3].std() > 0.01  # shaded, not flat
    fig.canvas.draw()


def test_lambert_bounds():
    base = np.ones((3, 3)) * 0.8
    n = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 0, -1.0]])
    c = viz.lambert(n, base, np.array([0, 0, 1.0]), ambient=0.3)
    np.testing.assert_allclose(c[:, 0], [0.8, 0.24, 0.8])  # facing the light: full; edge-on: ambient; two-sided


def test_point_colours_follow_colormap():
    fig, (ax,) = viz.figure(views=("front",))
    values = np.array([0.0, 0.5, 1.0])
    sc = viz.draw_points(ax, np.eye(3), values, cmap="viridis")
    top = np.array(plt.get_cmap("viridis")(1.0))
    np.testing.assert_allclose(sc.to_rgba(1.0), top)
    fig.canvas.draw()
    drawn = {tuple(np.round(c, 6)) for c in sc.get_facecolor()}
    assert tuple(np.round(top, 6)) in drawn
    assert len(fig.axes) == 2  # 3D axes + colorbar
    np.testing.assert_allclose(viz.value_colors([1.0, 2.0])[0], viz.CONTACT_CMAP(1.0))  # clipped to vmax
    np.testing.assert_allclose(viz.value_colors([0.0])[0], viz.CONTACT_CMAP(0.0))


def test_other_layers_draw(body):
    fig, (ax,) = viz.figure(views=("iso",))
    viz.draw_markers(ax, body.vertices[:3], labels=["a", "b", "c"])
    viz.draw_arrows(ax, [0, 0, 1], np.eye(3) * 0.3)
    viz.draw_goal(ax, [[0.5, 0, 1], [0, 0.5, 1]], radius=0.05)
    viz.draw_ground(ax, (-1, 1, -1, 1), step=0.5)
    viz.draw_path(ax, np.random.default_rng(0).normal(size=(10, 3)))
    fig.canvas.draw()
    v, f = viz.sphere([1, 2, 3], 0.5)
    np.testing.assert_allclose(np.linalg.norm(v - [1, 2, 3], axis=1), 0.5)
    assert trimesh.Trimesh(v, f).is_watertight


def test_ground_lines_every_step_on_a_room_and_bounded_on_a_far_scene():
    """A goal 1e9 m away once asked for a line every 0.25 m over the scene (a 44.7 GiB allocation)."""
    from graspkit.viz.scene import MAX_GROUND_LINES

    fig, (ax,) = viz.figure(views=("iso",))
    room = viz.draw_ground(ax, (-2, 2, -1, 1), step=0.25)
    far = viz.draw_ground(ax, (-1, 1e9, -1, 1), step=0.25)
    fig.canvas.draw()                                             # (3D segments are projected at draw time)
    assert len(room.get_segments()) == 17 + 9                     # every 0.25 m: x -2..2, y -1..1
    assert len(far.get_segments()) <= 2 * (MAX_GROUND_LINES + 1)
    with pytest.raises(ValueError, match="extent"):
        viz.draw_ground(ax, (0, float("inf"), 0, 1))


def test_show_scene_closes_its_figure_when_a_check_fails_and_names_nan_goals(ball):
    """A wrong mesh_values length or an unknown cmap, found while drawing, left the figure open; NaN goals were
    refused as `extent` (an independent check)."""
    v, f = ball.vertices, ball.faces
    before = plt.get_fignums()
    for kw in ({"mesh_values": [np.zeros(3)]}, {"cmap": "no_such_cmap", "mesh_values": [np.zeros(len(v))]}):
        with pytest.raises(ValueError):
            show_scene([(v, f)], **kw)
    with pytest.raises(ValueError, match="goals: contains NaN"):
        show_scene([(v, f)], goals=np.array([[np.nan, 0.0, 0.0]]))
    assert plt.get_fignums() == before


def test_show_scene(body, ball, tmp_path):
    pts = ball.vertices
    fig = viz.show_scene(meshes=[(body.vertices, body.faces), (ball.vertices, ball.faces, viz.OBJECT)],
                         points=pts, values=np.linspace(0, 1, len(pts)), markers=body.vertices[:2], labels=["p", "q"],
                         arrows=([0, 0, 1], [0.3, 0, 0]), goals=[0.5, -0.5, 1.2], paths=[body.vertices[:5]],
                         views=("front", "side", "top"), size=2, title="scene", colorbar_label="contact")
    axes3d = [a for a in fig.axes if isinstance(a, Axes3D)]
    assert len(axes3d) == 3 and len(fig.axes) == 4
    for ax in axes3d:
        r = np.array([np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())])
        a = np.asarray(ax.get_box_aspect())
        np.testing.assert_allclose(a / a[2], r / r[2], rtol=1e-6)
        assert ax.get_zlim()[0] <= 0.0 and ax.get_zlim()[1] >= body.bounds[1, 2]
    fig.savefig(tmp_path / "scene.png", dpi=50)
    with Image.open(tmp_path / "scene.png") as im:
        assert im.size[0] > 0


@pytest.mark.parametrize("call, name", [
    (lambda ax, b: viz.draw_mesh(ax, b.vertices[:, :2], b.faces), "mesh vertices"),
    (lambda ax, b: viz.draw_mesh(ax, b.vertices[None], b.faces), "mesh vertices"),
    (lambda ax, b: viz.draw_mesh(ax, b.vertices, b.faces[:, :2]), "mesh faces"),
    (lambda ax, b: viz.draw_mesh(ax, b.vertices[:10], b.faces), "mesh faces"),
    (lambda ax, b: viz.draw_points(ax, b.vertices, values=np.zeros(3)), "values"),
    (lambda ax, b: viz.draw_points(ax, np.zeros((4, 2))), "points"),
    (lambda ax, b: viz.draw_markers(ax, b.vertices[:3], labels=["a"]), "labels"),
    (lambda ax, b: viz.draw_arrows(ax, np.zeros((3, 3)), np.zeros((2, 3))), "vectors"),
    (lambda ax, b: viz.draw_goal(ax, [0, 0]), "center"),
    (lambda ax, b: viz.draw_ground(ax, (1, -1, 0, 1)), "extent"),
    (lambda ax, b: viz.figure(views=("nowhere",)), "views"),
    (lambda ax, b: animate_fn(b.vertices, b.faces), "frames"),
    (lambda ax, b: animate_fn(lambda t: b.vertices, b.faces), "num_frames"),
    (lambda ax, b: export_scene({"body": (b.vertices, b.faces[:, :2])}, "x.glb"), "body"),
    (lambda ax, b: export_scene({"body": b}, "x.stl"), "path"),
    (lambda ax, b: export_sequence_glb(b.vertices, b.faces, "x.glb"), "vertices"),
])
def test_wrong_shapes_name_the_argument(body, call, name):
    ax = viz.figure(views=("front",))[1][0]
    with pytest.raises(ValueError, match=name):
        call(ax, body)


# ---- animations ----

def test_gif_frames_and_stride(body, ball, tmp_path):
    frames = moving(body, 25)
    anim = animate_fn(frames, body.faces, objects=[(ball.vertices, ball.faces)], goals=[1, -1, 1],
                      views=("front", "top"), max_frames=10, size=1.5, dpi=40)
    assert isinstance(anim, FuncAnimation)
    path = save_animation(anim, tmp_path / "walk.gif")
    with Image.open(path) as im:
        assert im.format == "GIF" and im.n_frames == 9  # stride raised to ceil(25 / 10) = 3 -> frames 0, 3, ..., 24
    assert [p.name for p in tmp_path.iterdir()] == ["walk.gif"]  # the temporary file was renamed
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's owner-only mode


def test_an_animation_clears_a_killed_exports_temporary_file(body, tmp_path):
    """A `graspkit wandr --out` killed while its GIF was written left `.wandr_s0.gif.<random>.gif` for ever, through
    reruns (an independent check: the animation's temporary file keeps the .gif suffix, which the .tmp sweep missed);
    saving a GIF there now removes such files older than STALE_TMP_S and leaves a young one (a writer at work)."""
    import time

    from graspkit.paths import STALE_TMP_S

    stale, young = tmp_path / ".wandr_s0.gif.50wbkvk3.gif", tmp_path / ".other.gif.abcd1234.gif"
    for f, age in ((stale, STALE_TMP_S + 60), (young, 5)):
        f.write_bytes(b"")
        os.utime(f, (time.time() - age, time.time() - age))
    anim = animate_fn(moving(body, 3), body.faces, views=("front",), size=1.0, dpi=20)
    save_animation(anim, tmp_path / "wandr_s0.gif")
    assert sorted(p.name for p in tmp_path.iterdir()) == [young.name, "wandr_s0.gif"]


def test_a_gif_plays_at_real_time(body, tmp_path):
    """GIF delays are whole 1/100 s: Pillow's one int(1000 / fps) delay played 30 fps at 30 ms a frame, 10 % fast (an
    independent check); the delays now alternate (30, 40, 30 ms) so that they add up to the clip's length."""
    anim = animate_fn(moving(body, 31), body.faces, views=("front",), size=1.0, dpi=20, max_frames=31)
    with Image.open(save_animation(anim, tmp_path / "t.gif")) as im:
        delays = []
        for k in range(im.n_frames):
            im.seek(k)
            delays.append(im.info["duration"])
    assert len(delays) == 31 and set(delays) <= {30, 40}
    assert sum(delays) == pytest.approx(31 * 1000 / 30, abs=10)
    assert all(abs(sum(delays[:k]) - k * 1000 / 30) <= 5 for k in range(32))     # never more than half a step off


def test_animate_function_frames_and_moving_object(body, ball, tmp_path):
    obj = moving(ball, 6)
    anim = animate_fn(lambda t: torch.tensor(body.vertices) + t * 0.1, torch.tensor(body.faces), num_frames=6,
                      objects=[(obj, ball.faces, "green")], views=("side",), size=1.5, dpi=40)
    with Image.open(save_animation(anim, tmp_path / "f.gif", progress=True)) as im:
        assert im.n_frames == 6
    with pytest.raises(ValueError, match="objects"):
        animate_fn(moving(body, 4), body.faces, objects=[(obj, ball.faces)])


def test_decimated_sequence_keeps_one_topology(tmp_path):
    from graspkit.viz.animate import decimate_sequence

    sphere = trimesh.creation.icosphere(4)  # 5120 faces
    frames = [sphere.vertices, sphere.vertices + [1.0, 0.0, 0.5]]
    low, faces = decimate_sequence(frames, sphere.faces, 1000)
    assert abs(len(faces) - 1000) < 50 and len(low[0]) == len(low[1]) < len(sphere.vertices)
    shift = np.broadcast_to([1.0, 0.0, 0.5], low[0].shape)
    np.testing.assert_allclose(low[1] - low[0], shift, atol=1e-4)  # the simplifier works in float32
    anim = animate_fn(np.stack([v + [0.1 * t, 0, 0] for t, v in enumerate([sphere.vertices] * 3)]), sphere.faces,
                      max_faces=500, views=("front",), size=1.0, dpi=30)
    with Image.open(save_animation(anim, tmp_path / "d.gif")) as im:
        assert im.n_frames == 3


def test_html_embed_and_limit(body):
    anim = animate_fn(moving(body, 4), body.faces, views=("front",), size=1.5, dpi=40)
    html = to_html(anim)
    assert "<script" in html and len(html) < 3 * 2**20
    with pytest.raises(ValueError, match="max_mb"):
        to_html(anim, max_mb=0.001)


def test_save_errors_and_atomicity(body, tmp_path, monkeypatch):
    import sys

    anim_mod = sys.modules["graspkit.viz.animate"]  # the package attribute `animate` is the function
    anim = animate_fn(moving(body, 3), body.faces, views=("front",), size=1.0, dpi=30)
    with pytest.raises(ValueError, match="path"):
        save_animation(anim, tmp_path / "a.avi")
    monkeypatch.setattr(anim_mod, "_ffmpeg_path", lambda: None)
    with pytest.raises(RuntimeError, match=r"\.gif"):
        save_animation(anim, tmp_path / "a.mp4")

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(anim, "save", broken)
    with pytest.raises(OSError):
        save_animation(anim, tmp_path / "b.gif")
    assert list(tmp_path.iterdir()) == []  # no partial output, no temporary file left behind
    monkeypatch.undo()
    save_animation(anim, tmp_path / "b.gif")
    assert [p.name for p in tmp_path.iterdir()] == ["b.gif"]


def test_mp4_when_ffmpeg_available(body, tmp_path):
    import sys

    if sys.modules["graspkit.viz.animate"]._ffmpeg_path() is None:
        pytest.skip("no ffmpeg (install imageio-ffmpeg to test .mp4)")
    anim = animate_fn(moving(body, 5), body.faces, views=("front",), size=1.5, dpi=40)
    path = save_animation(anim, tmp_path / "a.mp4")
    assert path.stat().st_size > 1000 and path.read_bytes()[4:8] == b"ftyp"


# ---- export ----

@pytest.mark.parametrize("suffix", [".glb", ".obj", ".ply"])
def test_export_scene_round_trip(body, ball, tmp_path, suffix):
    meshes = {"body": (torch.tensor(body.vertices), body.faces), "ball": ball}
    path = export_scene(meshes, tmp_path / f"scene{suffix}", colors={"ball": "tab:green"})
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    loaded = trimesh.load_scene(path, process=False)
    n = len(body.vertices) + len(ball.vertices)
    assert sum(len(g.vertices) for g in loaded.geometry.values()) == n
    world = np.concatenate([body.vertices, ball.vertices])
    expect = world @ Z_UP_TO_Y_UP.T if suffix == ".glb" else world  # glTF is y up
    np.testing.assert_allclose(loaded.bounds, [expect.min(0), expect.max(0)], atol=1e-5)
    if suffix == ".glb":
        assert set(loaded.graph.nodes_geometry) == {"body", "ball"}
        assert len(loaded.geometry["body"].vertices) == len(body.vertices)
        np.testing.assert_allclose(loaded.geometry["body"].bounds[1, 1], body.bounds[1, 2], atol=1e-5)  # up is +y
    if suffix == ".obj":
        text = path.read_text()
        assert "o body" in text and "o ball" in text


def test_export_sequence_glb_round_trip(body, ball, tmp_path):
    frames = moving(body, 7)
    path = export_sequence_glb(torch.tensor(frames), body.faces, tmp_path / "seq.glb", fps=30,
                               objects={"ball": (ball.vertices, ball.faces)})
    v, f, times = load_sequence_glb(path)
    np.testing.assert_allclose(v, frames, atol=1e-5)
    np.testing.assert_array_equal(f, body.faces)
    np.testing.assert_allclose(times, np.arange(7) / 30, atol=1e-6)
    gltf, _ = read_glb(path)
    assert [n["name"] for n in gltf["nodes"]] == ["body", "ball"]
    assert len(gltf["meshes"][0]["primitives"][0]["targets"]) == 6
    assert gltf["animations"][0]["channels"][0]["target"] == {"node": 0, "path": "weights"}
    loaded = trimesh.load_scene(path, process=False)  # other tools see frame 0 and the object
    assert set(loaded.geometry) == {"body", "ball"}
    assert len(loaded.geometry["body"].vertices) == len(body.vertices)
    np.testing.assert_allclose(loaded.geometry["body"].vertices @ Z_UP_TO_Y_UP, frames[0], atol=1e-5)
    half = export_sequence_glb(frames, body.faces, tmp_path / "half.glb", stride=2)
    assert len(load_sequence_glb(half)[0]) == 4                  # frames 0, 2, 4, 6
    third = load_sequence_glb(export_sequence_glb(frames, body.faces, tmp_path / "third.glb", stride=4))
    np.testing.assert_allclose(third[0], frames[[0, 4, 6]], atol=1e-5)   # the last frame always kept
    np.testing.assert_allclose(third[2], np.array([0, 4, 6]) / 30, atol=1e-6)
    # a file cut short or empty is named (numpy's "buffer is smaller than requested size", a JSONDecodeError and a
    # struct.error named none, an independent check)
    data = path.read_bytes()
    import struct                                            # a chunk of unknown type is skipped, as glTF 2.0 asks
    n_json = struct.unpack_from("<I", data, 12)[0]
    extra = struct.pack("<II", 4, 0x12345678) + b"abcd"
    odd = data[:20 + n_json] + extra + data[20 + n_json:]
    (tmp_path / "odd.glb").write_bytes(odd[:8] + struct.pack("<I", len(odd)) + odd[12:])
    np.testing.assert_allclose(load_sequence_glb(tmp_path / "odd.glb")[0], frames, atol=1e-5)
    for n, message in ((len(data) // 2, "is cut short or padded"), (900, "is cut short or padded"),
                       (0, "is not a glTF 2.0 binary file")):
        cut = tmp_path / f"cut{n}.glb"
        cut.write_bytes(data[:n])
        for read in (read_glb, load_sequence_glb):
            with pytest.raises(ValueError, match=f"^path: {cut} {message}"):
                read(cut)


def test_strided_animation_plays_at_real_time_and_stamps_clip_times():
    """`animate` plays at real time with a stride (every stride-th frame shown for stride / fps s) and stamps a drawn
    frame with its clip frame's time."""
    v = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]], float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    frames = np.stack([v + [0.01 * t, 0, 0] for t in range(12)])
    anim = animate_fn(frames, f, fps=30.0, stride=3, max_frames=None, views=("front",), ground=False)
    assert anim._interval == 100.0                                  # 3 frames of a 30 fps clip: 0.1 s each
    assert anim.graspkit_fps == 10.0
    anim._func(2)                                                   # the third drawn frame is clip frame 6
    assert anim._fig.texts[0].get_text().strip() == "t = 0.20 s"
    anim._draw_was_started = True                                   # (never rendered on purpose: no warning)


def test_sphere_is_closed_and_wound_outward():
    """viz.scene.sphere is a closed mesh wound outward, as trimesh sees it."""
    c = np.array([0.3, -0.2, 1.1])
    v, f = sphere(c, 0.05, n=8)
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    out = ((m.triangles_center - c) * m.face_normals).sum(1)
    assert (out > 0).all()
    np.testing.assert_allclose(np.linalg.norm(v - c, axis=1), 0.05, atol=1e-12)


def test_a_strided_animation_draws_the_moving_object_at_the_drawn_frames(tmp_path):
    """stride=4 over 20 frames draws frames 0, 4, .., 16 and the last, 19: an object moving 5 m along x over the clip
    is drawn up to x = 5 m, so the panel's x range reaches past 5 m (a static body at the origin)."""
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    body = trimesh.creation.box((0.3, 0.3, 1.0))
    T = 20
    obj = np.stack([box.vertices + [5.0 * t / (T - 1), 0.0, 0.5] for t in range(T)])
    anim = animate_fn(np.stack([body.vertices] * T), body.faces, objects=[(obj, box.faces)], stride=4,
                      views=("top",), size=1.5, dpi=30, ground=False)
    fig = anim._fig
    hi = fig.axes[0].get_xlim3d()[1]
    assert hi > 5.0
    with Image.open(save_animation(anim, tmp_path / "strided.gif")) as im:      # rendered: the 6 drawn frames
        assert im.n_frames == 6
    plt.close(fig)


def test_ground_lines_stay_inside_the_extent():
    """draw_ground(ax, (x0, x1, y0, y1)): the lines of constant x run from y0 to y1, those of constant y from x0 to
    x1; none leaves the rectangle."""
    fig, (ax,) = viz.figure(views=("iso",))
    lc = viz.draw_ground(ax, (-2, 2, -1, 1), step=0.5)
    assert isinstance(lc, Line3DCollection)
    seg = np.asarray(lc._segments3d, float)                   # (n, 2, 3)
    assert (seg[..., 0] >= -2 - 1e-9).all() and (seg[..., 0] <= 2 + 1e-9).all()
    assert (seg[..., 1] >= -1 - 1e-9).all() and (seg[..., 1] <= 1 + 1e-9).all()
    const_x = seg[np.isclose(seg[:, 0, 0], seg[:, 1, 0])]
    assert len(const_x) == 9 and np.allclose(np.sort(const_x[:, :, 1], 1), [[-1, 1]] * 9)
    plt.close(fig)


def test_scene_face_indices_padding_alpha_goals_and_ground():
    """Face indices must lie in [0, V) (V itself and -1 are refused); set_equal pads each side by `pad`; draw_mesh's
    alpha reaches every face colour; goal spheres of radius r fit in the limits; the ground grid lies on z = 0 under a
    floating scene."""
    from graspkit import viz
    from graspkit.viz.scene import as_mesh

    v = np.eye(3)
    for bad in ([[0, 1, 3]], [[0, 1, -1]]):
        with pytest.raises(ValueError, match="faces: indices must lie in"):
            as_mesh(v, bad)
    fig, (ax,) = viz.figure(views=("front",))
    lim = viz.set_equal(ax, np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 1.0]]), pad=0.1)
    np.testing.assert_allclose(lim, [[-0.1, -0.1, -0.1], [2.1, 1.1, 1.1]])
    pc = viz.draw_mesh(ax, v, [[0, 1, 2]], alpha=0.3)
    np.testing.assert_allclose(np.asarray(pc.get_facecolor())[:, 3], 0.3)
    plt.close(fig)
    fig = viz.show_scene(goals=[0.0, 0.0, 1.0], goal_radius=0.2, ground=False, views=("front",), size=1.0)
    ax = fig.axes[0]
    assert ax.get_xlim()[0] <= -0.2 + 1e-9 and ax.get_xlim()[1] >= 0.2 - 1e-9
    assert ax.get_zlim()[0] <= 0.8 + 1e-9 and ax.get_zlim()[1] >= 1.2 - 1e-9
    plt.close(fig)
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    fig = viz.show_scene(meshes=[(box.vertices + [0, 0, 1.0], box.faces)], views=("front",), size=1.0)
    from mpl_toolkits.mplot3d.art3d import Line3DCollection
    [grid] = [c for c in fig.axes[0].collections if isinstance(c, Line3DCollection)]
    np.testing.assert_allclose(np.asarray(grid._segments3d, float)[..., 2], 0.0)
    plt.close(fig)


def _drawn(anim, i):
    """The 3D triangles (F,3,3) the animation's first panel holds after drawing frame i."""
    anim._func(i)
    [pc] = [c for c in anim._fig.axes[0].collections if type(c).__name__ == "Poly3DCollection"]
    return np.asarray(pc._faces)


def test_animation_draws_body_and_moving_object_at_the_drawn_clip_frames():
    """stride 2 over 7 frames draws clip frames 0, 2, 4, 6: drawn frame i shows the body (a list of frames) and the
    moving object at clip frame 2 i (their x positions are the clip's, by construction)."""
    v, f = _tet()
    v = v - v.mean(0)
    body = [v + [0.0, 0.0, 0.5 * t] for t in range(7)]              # body rises 0.5 m per frame
    obj = np.stack([v + [1.0 * t, 0.0, 0.0] for t in range(7)])     # object moves 1 m per frame along x
    anim = animate_fn(body, f, objects=[(obj, f)], stride=2, max_frames=None, views=("front",), ground=False)
    for i, k in enumerate([0, 2, 4, 6]):
        tri = _drawn(anim, i)
        assert len(tri) == 8                                          # two tets: body and object
        want = (body[k].mean(0) + obj[k].mean(0)) / 2                 # each tet vertex lies on 3 of its 4 faces
        np.testing.assert_allclose(tri.reshape(-1, 3).mean(0), want, atol=1e-9)
    anim._draw_was_started = True
    plt.close(anim._fig)


def test_animation_always_draws_the_last_frame():
    """stride 5 over 12 frames draws clip frames 0, 5, 10 and then 11, the last (a reach ends there): its drawn frame
    shows the body and the moving object at frame 11 and is stamped with frame 11's time."""
    v, f = _tet()
    v = v - v.mean(0)
    body = np.stack([v + [0.0, 0.0, 0.5 * t] for t in range(12)])
    obj = np.stack([v + [1.0 * t, 0.0, 0.0] for t in range(12)])
    anim = animate_fn(body, f, objects=[(obj, f)], fps=30.0, stride=5, max_frames=None, views=("front",), ground=False)
    assert anim._save_count == 4
    for i, k in enumerate([0, 5, 10, 11]):
        np.testing.assert_allclose(_drawn(anim, i).reshape(-1, 3).mean(0), (body[k].mean(0) + obj[k].mean(0)) / 2,
                                   atol=1e-9)
    assert anim._fig.texts[0].get_text().strip() == "t = 0.37 s"
    anim._draw_was_started = True
    plt.close(anim._fig)


def test_animation_refuses_a_stride_below_one():
    """stride 0 or -1 is no step through the clip: a ValueError naming stride, even with max_frames raising it."""
    v, f = _tet()
    for s in (0, -1):
        with pytest.raises(ValueError, match="stride"):
            animate_fn(np.stack([v, v]), f, stride=s, views=("front",))
    plt.close("all")


def test_gif_plays_at_real_time_and_honours_an_explicit_fps(tmp_path):
    """A 20 fps clip drawn every 2nd frame plays each GIF frame for 2/20 s = 100 ms; save_animation(fps=4) plays
    4 drawn frames per second (250 ms), read back by PIL."""
    v, f = _tet()
    frames = np.stack([v + [0.1 * t, 0.05 * (t % 2), 0.0] for t in range(5)])  # frames 0, 2, 4: 4 is the last
    anim = animate_fn(frames, f, fps=20.0, stride=2, max_frames=None, views=("front",), size=1.0, dpi=30)
    for fps, ms in ((None, 100), (4.0, 250)):
        path = save_animation(anim, tmp_path / f"a{ms}.gif", fps=fps)
        with Image.open(path) as im:
            assert im.n_frames == 3
            durations = []
            for k in range(im.n_frames):
                im.seek(k)
                durations.append(im.info["duration"])
        assert durations == [ms] * 3, durations


def test_to_html_limit_is_in_megabytes_of_the_encoded_page():
    """max_mb compares the page's UTF-8 size in MB (2**20 bytes): a limit just under the page's size refuses it, one
    just over accepts it."""
    v, f = _tet()
    anim = animate_fn(np.stack([v, v + 0.1]), f, views=("front",), size=1.0, dpi=30)
    mb = len(to_html(anim, max_mb=100).encode()) / 2**20
    to_html(anim, max_mb=mb * 1.05)
    with pytest.raises(ValueError, match="max_mb"):
        to_html(anim, max_mb=mb * 0.95)
