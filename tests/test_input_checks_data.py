"""Bad input to the sequence readers, writers and exports gives a clear error naming the argument, key or file, and
nothing is written half-way."""
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch
import trimesh

from graspkit import metrics
from graspkit.data import Motion, load_motion, save_motion
from graspkit.data.formats import SequenceFileError
from graspkit.data.grab import GraspSequence, load_grasp_sequence, save_grasp_sequence
from graspkit.viz.export import export_motion, export_sequence_glb

CLIP = sorted((Path(__file__).resolve().parents[1] / "data_stubs" / "motion" / "reach").glob("*.npz"))[0]


@pytest.fixture(scope="module")
def clip() -> Motion:
    return load_motion(CLIP).slice(0, 4)


def _grasp(T: int = 4, points: bool = True) -> GraspSequence:
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(16, 3)) if points else None
    return GraspSequence(rng.normal(scale=0.3, size=(T, 55, 3)), rng.normal(size=(T, 3)), rng.normal(size=10), 30.0,
                         "mug", rng.normal(size=(T, 3)), rng.normal(size=(T, 3)), object_points=pts,
                         object_normals=pts)


def _grasp_file(tmp_path: Path, name: str, **replace) -> Path:
    """A saved grasp sequence with some keys replaced."""
    good = save_grasp_sequence(tmp_path / "good.npz", _grasp())
    with np.load(good) as z:
        arrays = {**dict(z), **replace}
    np.savez(tmp_path / name, **arrays)
    return tmp_path / name


# ---- Motion.iter_vertices / metrics.motion_quality

@pytest.mark.parametrize("chunk, overlap", [(1, 1), (0, 0), (2, 3)])
def test_iter_vertices_needs_chunk_above_overlap(bm, clip, chunk, overlap):
    with pytest.raises(ValueError, match="chunk"):
        clip.iter_vertices(bm, chunk=chunk, overlap=overlap)


def test_motion_quality_chunk_1_is_an_error_not_a_hang(bm, clip):
    with pytest.raises(ValueError, match="chunk"):
        metrics.motion_quality(bm, [clip], chunk=1)


# ---- GRAB-style grasp files

@pytest.mark.parametrize("rate", [0.0, -30.0, np.nan])
def test_grasp_file_framerate_must_be_positive(tmp_path, rate):
    p = _grasp_file(tmp_path, "rate.npz", framerate=np.array(rate))
    with pytest.raises(SequenceFileError, match=r"rate\.npz: key 'framerate'"):
        load_grasp_sequence(p)


def test_grasp_file_wrong_frame_count_names_key_and_shape(tmp_path):
    p = _grasp_file(tmp_path, "short.npz", **{"object.params.transl": np.zeros((2, 3), np.float32)})
    with pytest.raises(SequenceFileError, match=r"short\.npz: key 'object.params.transl' has shape \(2, 3\), "
                                                r"expected \(4, 3\)"):
        load_grasp_sequence(p)


def test_grasp_file_npy_is_a_clear_error(tmp_path):
    np.save(tmp_path / "one.npy", np.zeros(3))
    with pytest.raises(SequenceFileError, match=r"one\.npy: expected an \.npz"):
        load_grasp_sequence(tmp_path / "one.npy")


@pytest.mark.parametrize("key, value", [("object.params.global_orient", np.full((4, 3), np.inf, np.float32)),
                                        ("body.betas", np.full(10, np.nan, np.float32)),
                                        ("object.points", np.full((16, 3), np.nan, np.float32))])
def test_grasp_file_non_finite_values_are_refused(tmp_path, key, value):
    p = _grasp_file(tmp_path, "nan.npz", **{key: value})
    with pytest.raises(SequenceFileError, match=rf"nan\.npz: key '{key}' contains NaN"):
        load_grasp_sequence(p)


def test_save_grasp_points_without_normals_writes_nothing(tmp_path):
    s = _grasp()
    s.object_normals = None
    with pytest.raises(ValueError, match="object_normals"):
        save_grasp_sequence(tmp_path / "pts.npz", s)
    assert not list(tmp_path.iterdir())


# ---- exports and AMASS-style sequence files

def test_export_nan_pose_writes_nothing(bm, clip, tmp_path):
    bad = Motion(clip.poses.copy(), clip.trans, clip.betas)
    bad.poses[1, 3, 0] = np.nan
    with pytest.raises(ValueError, match="poses"):
        export_motion(bad, bm, tmp_path / "out", "nan", stride=1)
    with pytest.raises(ValueError, match="poses"):
        save_motion(tmp_path / "nan.npz", bad)
    assert not list(tmp_path.rglob("*"))


def test_export_sequence_glb_needs_positive_fps_and_stride(tmp_path):
    v, f = np.zeros((3, 4, 3)), [[0, 1, 2]]
    with pytest.raises(ValueError, match="fps"):
        export_sequence_glb(v, f, tmp_path / "f0.glb", fps=0)
    with pytest.raises(ValueError, match="stride"):
        export_sequence_glb(v, f, tmp_path / "s0.glb", stride=0)
    v[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="vertices"):
        export_sequence_glb(v, f, tmp_path / "nan.glb")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("kwargs, error, message", [
    (dict(stride=0), ValueError, "stride"),
    (dict(objects=[np.zeros((3, 3))]), TypeError, "objects"),
    (dict(objects={"box": "not a mesh"}), ValueError, "box"),
    (dict(objects={"box": trimesh.Trimesh(np.full((3, 3), np.nan), [[0, 1, 2]], process=False)}), ValueError, "box"),
])
def test_export_motion_checks_arguments_before_writing(bm, clip, tmp_path, kwargs, error, message):
    with pytest.raises(error, match=message):
        export_motion(clip, bm, tmp_path, "clip", **kwargs)
    assert not list(tmp_path.iterdir())


def test_export_motion_zero_frames_is_a_clear_error(bm, clip, tmp_path):
    """A 0-frame motion is refused where it is made (Motion itself, as slice(0, 0) is), so no export sees one."""
    with pytest.raises(ValueError, match="^poses: expected at least one frame"):
        export_motion(Motion(clip.poses[:0], clip.trans[:0], clip.betas), bm, tmp_path, "empty")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("fps", [0.0, -30.0, np.nan, np.inf])
def test_motion_and_load_motion_need_positive_fps(clip, fps):
    with pytest.raises(ValueError, match="fps"):
        Motion(clip.poses, clip.trans, clip.betas, fps=fps)
    with pytest.raises(ValueError, match=rf"fps: .*{CLIP.name}"):
        load_motion(CLIP, fps=fps)


def test_file_with_zero_frame_rate_names_the_file(clip, tmp_path):
    p = save_motion(tmp_path / "m.npz", clip)
    with np.load(p) as z:
        np.savez(tmp_path / "rate0.npz", **{**dict(z), "mocap_frame_rate": np.array(0.0)})
    with pytest.raises(SequenceFileError, match=r"rate0\.npz: key 'mocap_frame_rate'"):
        load_motion(tmp_path / "rate0.npz")


@pytest.mark.parametrize("change, message", [
    ({"poses": np.zeros((0, 165), np.float32), "trans": np.zeros((0, 3), np.float32)}, "key 'poses' has 0 frames"),
    ({"goal": np.array([0.3, np.nan, 1.0], np.float32)}, "key 'goal' contains NaN"),
])
def test_a_file_with_no_frames_or_a_nan_goal_names_the_file(tmp_path, change, message):
    m = load_motion(CLIP)                                    # a reaching clip: it has a goal
    with np.load(save_motion(tmp_path / "m.npz", m)) as z:
        np.savez(tmp_path / "odd.npz", **{**dict(z), **change})
    with pytest.raises(SequenceFileError, match=rf"odd\.npz: {message}"):
        load_motion(tmp_path / "odd.npz")
    load_motion(tmp_path / "m.npz")                          # the file it was made from loads


def test_betas_count_matches_num_betas(clip, tmp_path):
    few = save_motion(tmp_path / "b5.npz", Motion(clip.poses, clip.trans, np.arange(1, 6)), amass_keys=True)
    many = save_motion(tmp_path / "b16.npz", Motion(clip.poses, clip.trans, np.arange(1, 17)), amass_keys=True)
    for p, want in ((few, [1, 2, 3, 4, 5, 0, 0, 0, 0, 0]), (many, list(range(1, 11)))):
        with np.load(p) as z:
            assert z["betas"].tolist() == want and int(z["num_betas"]) == len(z["betas"]) == 10
    assert np.array_equal(load_motion(few).betas[:5], np.arange(1, 6))


# ---- demo figures

def test_figures_are_saved_atomically(tmp_path, monkeypatch):
    from graspkit.viz.export import save_png

    path = tmp_path / "fig.png"
    path.write_bytes(b"old")
    fig = plt.figure()
    monkeypatch.setattr(fig, "savefig", lambda *a, **k: (_ for _ in ()).throw(RuntimeError("render failed")))
    with pytest.raises(RuntimeError, match="render failed"):
        save_png(fig, path, dpi=50)
    assert path.read_bytes() == b"old" and [q.name for q in tmp_path.iterdir()] == ["fig.png"]
    assert save_png(plt.figure(figsize=(1, 1)), path, dpi=20) == path
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and [q.name for q in tmp_path.iterdir()] == ["fig.png"]


@pytest.mark.parametrize("call", ["generate_locomotion", "generate_reach", "generate_reach_chain", "plan_reach",
                                  "within_reach_pose", "split_clips", "validation_goals", "goal_row_schedules",
                                  "random_smplx_arrays"])
def test_a_seeded_function_refuses_seed_none(call):
    """`seed=None` would make numpy draw from the OS: the same call, other numbers. Each seeded entry point refuses it
    (and a bool, a fraction, a negative seed) before any work, naming `seed`."""
    from graspkit.body.random_model import random_smplx_arrays
    from graspkit.data import generate_locomotion, generate_reach, plan_reach
    from graspkit.data.motionfill_dataset import split_clips
    from graspkit.data.reaching import Start, generate_reach_chain
    from graspkit.eval_wandr import goal_row_schedules, validation_goals
    from graspkit.objects.placement import within_reach_pose

    fn = {"generate_locomotion": lambda s: generate_locomotion(s, None),
          "generate_reach": lambda s: generate_reach(s, None),
          "generate_reach_chain": lambda s: generate_reach_chain(s, None),
          "plan_reach": lambda s: plan_reach(Start(0, 0, 0), (1.0, 0.0, 1.0), 30, seed=s),
          "within_reach_pose": within_reach_pose, "split_clips": lambda s: split_clips(10, seed=s),
          "validation_goals": lambda s: validation_goals(4, seed=s),
          "goal_row_schedules": lambda s: goal_row_schedules(2, seed=s),
          "random_smplx_arrays": lambda s: random_smplx_arrays(100, 40, seed=s)}[call]
    for bad in (None, True, 1.5, -1):
        with pytest.raises(ValueError, match=r"^seed: expected an integer >= 0, got "):
            fn(bad)


def test_slice_ending_at_the_goal_frame_drops_the_goal():
    """A slice keeps the goal only when the goal frame lies inside it, the end excluded; a negative start counts from
    the end (the goal frame was shifted by the negative start and lost)."""
    m = load_motion(CLIP)
    g = m.goal_frame
    assert g is not None and g > 0
    before = m.slice(0, g)                          # frames 0..g-1: the goal frame just outside
    assert before.num_frames == g and before.goal is None and before.goal_frame is None
    upto = m.slice(1, g + 1)
    assert upto.goal_frame == g - 1 and np.array_equal(upto.goal, m.goal)
    tail = m.slice(g - m.num_frames)                # a negative start counts from the end, as numpy's slicing
    assert tail.num_frames == m.num_frames - g and tail.goal_frame == 0 and np.array_equal(tail.goal, m.goal)
    np.testing.assert_array_equal(tail.poses, m.poses[g:])


def test_iter_vertices_chunks_overlap_and_match_the_whole_clip(bm):
    """Each chunk starts `overlap` frames before the last one ended and holds Motion.vertices of its frames."""
    m = load_motion(CLIP).slice(0, 11)
    whole = m.vertices(bm)
    starts = []
    for start, v in m.iter_vertices(bm, chunk=4, overlap=1):
        starts.append(start)
        torch.testing.assert_close(v, whole[start:start + len(v)], rtol=0, atol=1e-5)
    assert starts == [0, 3, 6, 9]


# ------------------------------------------------------------------- the motion and grasp generators' arguments
def test_the_planners_and_generators_name_a_bad_argument(bm):
    """Each was taken silently or failed deep inside numpy before (an independent check of the motion data): a goal
    frame too soon for a step (the wrist 8-12 cm off the stored goal), a zero / NaN / negative v_pref, a 2-D or
    short or NaN betas, num_frames 0 (a random length) or -5 (a 20-frame clip), a goal of two coordinates, a start
    of two values."""
    from graspkit.data.locomotion import generate_locomotion
    from graspkit.data.reaching import MIN_GOAL_FRAMES, Start, generate_reach_chain, plan_reach

    goal = (0.5, -0.2, 1.0)
    with pytest.raises(ValueError, match=f"t_goal_frames: expected an integer >= {MIN_GOAL_FRAMES}"):
        plan_reach(Start(), goal, MIN_GOAL_FRAMES - 1, bm=bm)
    for v in (0.0, float("nan"), -1.0, 2.5, True):
        with pytest.raises(ValueError, match=r"v_pref: expected a walking speed in \(0, 1.6\] m/s"):
            plan_reach(Start(), goal, 30, bm=bm, v_pref=v)
    with pytest.raises(ValueError, match=r"goal: expected a finite point \(3,\)"):
        plan_reach(Start(), (1.0, 0.0), 30, bm=bm)
    with pytest.raises(ValueError, match=r"start: expected a Start or \(x, y, heading\)"):
        plan_reach((0.0, 0.0), goal, 30, bm=bm)
    for betas in (np.zeros((2, 10)), np.ones(3), np.full(10, np.nan)):
        with pytest.raises(ValueError, match="^betas: expected at least 10 finite shape coefficients"):
            generate_locomotion(1, bm, num_frames=30, betas=betas)
    with pytest.raises(ValueError, match="^betas:"):
        generate_reach_chain(1, bm, betas=np.full(10, np.nan))
    for n in (0, -5, True, 2.5, "60"):
        with pytest.raises(ValueError, match="^num_frames: expected an integer >= 1"):
            generate_locomotion(1, bm, num_frames=n)
    from graspkit.data.reaching import plan_reach_chain

    with pytest.raises(ValueError, match=f"goal_frames: the second goal frame must come at least {MIN_GOAL_FRAMES}"):
        plan_reach_chain(Start(), np.array([goal, (1.5, 0.0, 1.0)]), (30, 30 + 10 + 24 + MIN_GOAL_FRAMES - 1), (10, 10),
                         bm=bm)                    # a second leg of 8 frames left the wrist 17-36 cm off its goal
    m = plan_reach(Start(), goal, MIN_GOAL_FRAMES, bm=bm, hold_frames=0)         # the shortest time is met
    wrist = m.joint_positions(bm)[MIN_GOAL_FRAMES, 21]
    assert np.linalg.norm(wrist - np.asarray(goal)) < 1e-3


def test_a_motion_keeps_goal_frame_and_hand_only_with_a_goal_and_a_whole_goal_frame(clip):
    """Motion(goal_frame=2.7) was truncated to 2 (load_motion refuses it in a file), and a goal_frame or hand without
    a goal was kept and then dropped by save_motion without a word."""
    args = (clip.poses, clip.trans, clip.betas)
    with pytest.raises(ValueError, match="goal_frame: expected a whole frame"):
        Motion(*args, goal=(0, 0, 1), goal_frame=2.7, hand="right")
    with pytest.raises(ValueError, match="goal_frame, hand: given .* without a goal"):
        Motion(*args, goal_frame=2, hand="right")
    assert Motion(*args, goal=(0, 0, 1), goal_frame=np.int64(2), hand="right").goal_frame == 2
    assert Motion(*args, goal=(0, 0, 1), goal_frame=np.array(2), hand="right").goal_frame == 2    # as read from a file
    with pytest.raises(ValueError, match=r"betas: expected one body's shape coefficients \(K,\)"):
        Motion(clip.poses, clip.trans, np.zeros((2, 10)))
    assert Motion(clip.poses, clip.trans, np.zeros((1, 10))).betas.shape == (10,)


def test_the_datasets_name_bad_windows_splits_and_statistics(bm):
    """WANDR: samples=0 gave NaN intention statistics, a horizon below the window put t_G inside it, a clip index out
    of range was a bare IndexError, a fractional max_steps was taken; MotionFill: fractions over 1 or negative and a
    negative clip count were split silently."""
    from graspkit.data import motionfill_dataset as MF
    from graspkit.data import wandr_dataset as W

    clips = W.clips_from_motions([load_motion(p) for p in sorted(CLIP.parent.glob("*.npz"))[:2]], ["a", "b"], bm)
    for samples in (0, 1, -5):
        with pytest.raises(ValueError, match="^samples: expected an integer >= 2"):
            W.compute_stats(clips, samples=samples)
    items = torch.tensor([[0, 5]])
    with pytest.raises(ValueError, match="^horizon: expected an integer >= 1"):
        W.make_batch(clips, items, steps=10, horizon=0)
    loco = W.clips_from_motions([load_motion(p) for p in sorted((CLIP.parent.parent / "locomotion").glob("*.npz"))[:1]],
                                ["l"], bm)
    b = W.make_batch(loco, torch.tensor([[0, 5]] * 4), steps=10, horizon=5, generator=torch.Generator().manual_seed(0))
    assert b["hindsight"].all() and (b["t_goal"] == 11).all()     # a horizon under the window: its last frame
    with pytest.raises(ValueError, match="^steps: expected an integer >= 0"):
        W.make_batch(clips, items, steps=-1)
    with pytest.raises(ValueError, match=r"^items: clip indices expected in \[0, 2\)"):
        W.make_batch(clips, torch.tensor([[5, 5]]), steps=2)
    for bad in (2.5, True, -1):
        with pytest.raises(ValueError, match="^max_steps: expected an integer >= 0"):
            W.WindowDataset(clips, max_steps=bad)
    for fractions in ((0.9, 0.3), (-0.2, 0.1), (0.8,)):
        with pytest.raises(ValueError, match="^fractions: expected two non-negative numbers"):
            MF.split_clips(10, fractions=fractions)
    for n in (-3, 10.5):
        with pytest.raises(ValueError, match="^num_clips: expected an integer >= 0"):
            MF.split_clips(n)
    s = MF.split_clips(10, fractions=(0.6, 0.4))
    assert (len(s["train"]), len(s["val"]), len(s["test"])) == (6, 4, 0)


def test_hand_poses_rig_and_gnet_layouts_are_checked(bm, tmp_path):
    """sample_hand_poses passed n, noise_deg and rng to numpy unchecked; generate_locomotion took a rig of another
    body (the body then floated 14-16 cm above the floor); GNetDataset took the GOAL layout of its first file for
    all (independent checks)."""
    import shutil

    from graspkit.body.hand_poses import sample_hand_poses
    from graspkit.data.grasp_datasets import GNetDataset
    from graspkit.data.locomotion import generate_locomotion
    from graspkit.data.rig import build_rig

    for kwargs, message in (({"n": -1}, "^n: expected an integer >= 0"), ({"n": 2.5}, "^n:"),
                            ({"noise_deg": -5.0}, "^noise_deg: expected a finite number >= 0"),
                            ({"noise_deg": float("nan")}, "^noise_deg:"), ({"rng": -1}, "^rng: expected an integer")):
        with pytest.raises(ValueError, match=message):
            sample_hand_poses(**{"n": 2, **kwargs})
    with pytest.raises(ValueError, match="^rig: built for another body"):
        generate_locomotion(5, bm, num_frames=30, kind="walk", betas=np.full(10, -2.0), rig=build_rig(bm, np.zeros(10)))
    m = generate_locomotion(5, bm, num_frames=30, kind="walk", betas=np.zeros(10), rig=build_rig(bm, np.zeros(10)))
    assert m.num_frames == 30
    stubs = Path(__file__).resolve().parents[1] / "data_stubs" / "grasps"
    files = sorted(stubs.glob("grasp_*.npz"))[:2]
    for f in files:
        shutil.copy(f, tmp_path / f.name)
    with np.load(files[1], allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["goal.vertex_ids"] = arrays["goal.vertex_ids"][::-1].copy()
    np.savez(tmp_path / files[1].name, **arrays)
    with pytest.raises(ValueError, match="goal.vertex_ids' differs from"):
        GNetDataset(tmp_path, split=None)
