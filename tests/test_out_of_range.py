"""Requests past what the models were trained and measured for get a GraspkitWarning saying what to expect (an
independent check drove WANDR, SAGA and the body out of range, 2026-12-06), and pictures put the floor at z = 0."""
import warnings

import numpy as np
import pytest
import torch

from graspkit.checks import GraspkitWarning
from graspkit.paths import DATA_STUBS


@pytest.fixture(scope="module")
def wandr():
    from graspkit.eval_wandr import starts_from_meta
    from graspkit.models.wandr import load_wandr

    model = load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt")
    return model, starts_from_meta(model.meta)[0]


def _notes(model, start, goals, t_goal) -> list[str]:
    """The RangeWarnings of one generate call (one frame generated: the notes come from the request)."""
    from graspkit.models.wandr import RangeWarning, generate

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        generate(model, start, torch.tensor(goals, dtype=torch.float32), t_goal, frames=1,
                 generator=torch.Generator().manual_seed(0))
    return [str(w.message) for w in caught if issubclass(w.category, RangeWarning)]


def test_generate_warns_for_goals_out_of_range_and_names_the_worst_sequence(wandr):
    """45 m in 30 s ended 2 m above the floor, a goal 1 m under it took the body 48 cm under: the library said nothing
    (only `graspkit wandr` did). In range (the grid's farthest: 5 m in 8 s, 1.8 m high) it stays quiet."""
    model, start = wandr
    x, y = start.p[:2].tolist()
    assert _notes(model, start, [[x + 5.0, y, 1.8], [x, y + 0.5, 0.0]], 239) == []
    notes = _notes(model, start, [[x + 1.2, y, 1.0], [x + 40.0, y, 1.0], [x + 1.0, y, -1.0]],
                   torch.tensor([30, 900, 120]))
    assert len(notes) == 2, notes                  # 40 m in 30 s is 1.3 m/s: no speed note
    assert notes[0].startswith("sequence 1 of the batch: 30 s is past the 8 s") and "by metres" in notes[0]
    assert notes[1].startswith("sequence 2 of the batch: the goal is 1.00 m below the floor")
    (speed,) = _notes(model, start, [x + 8.0, y, 1.0], 120)                   # one goal: no sequence named
    assert speed.startswith("the goal is 8.0 m away: 2.0 m/s on average, faster than the 1.5 m/s")
    (high,) = _notes(model, start, [x + 1.0, y, 2.5], 120)
    assert high.startswith("the goal is 2.50 m high")


def test_generate_measures_the_goals_distance_from_the_pelvis(wandr):
    """The speed note measured from the pose's translation, which the held-out starts' rest pelvis sits ~0.35 m off:
    a goal 1.3 m from the pelvis in 1 s was called 1.7 m/s, one 1.6 m away passed (an independent check). Now, on
    every side of the pelvis (posed by forward kinematics), 1.42 m/s is quiet and 1.58 m/s is named."""
    from graspkit import intention as I

    model, start = wandr
    pelvis = I.body_joints(start.p[None], start.rest[None])[0, I.PELVIS]
    assert float((pelvis[:2] - start.p[:2]).norm()) > 0.2                  # the case that told them apart
    for angle in np.deg2rad([0.0, 90.0, 180.0, 270.0]):
        way = torch.tensor([np.cos(angle), np.sin(angle), 0.0], dtype=torch.float32)
        goal = lambda d: [*(pelvis[:2] + d * way[:2]).tolist(), 1.0]           # noqa: E731 - 1 m up
        assert _notes(model, start, [goal(1.42)], 30) == []
        (note,) = _notes(model, start, [goal(1.58)], 30)
        assert note.startswith("the goal is 1.6 m away: 1.6 m/s on average"), note


def test_betas_beyond_the_checked_range_are_warned_about():
    """All ten betas at -5 make a 0.94 m, 2 L body with joints outside it: taken silently before."""
    from graspkit.checks import check_betas

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_betas(np.full(10, 2.0), 10)
        check_betas(np.full(10, -2.0), 10)
    with pytest.warns(GraspkitWarning, match=r"betas: coefficient 3 is -5, outside the ±2"):
        check_betas(np.array([0, 1, -2, -5, 0, 0, 0, 0, 0, 0.0]), 10)


def test_saga_warns_for_a_start_too_far_for_a_two_second_walk():
    """3 m in MotionFill's 2 s peaked at 4.4 m/s with both feet off the floor; the warning comes before any work."""
    from graspkit.saga import synthesize

    with pytest.warns(GraspkitWarning, match=r"start_distance: 2 m; covered in MotionFill's 2 s that is a run"), \
            pytest.raises(ValueError, match="grasp_steps"):
        synthesize("mug", start_distance=2.0, grasp_steps=(0,))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="grasp_steps"):
            synthesize("mug", start_distance=1.5, grasp_steps=(0,))


def test_interpolated_trajectory_takes_a_windows_root_states_only():
    """A 122-frame trajectory was read at its frame 60 (not its end), a 30-frame one failed inside numpy."""
    from graspkit.data.motionfill_dataset import NUM_ROOT, global_motion, interpolated_trajectory

    traj = np.zeros((NUM_ROOT, 4))
    traj[:, 0], traj[:, 2] = np.linspace(0, 1.0, NUM_ROOT), 1.0
    out = interpolated_trajectory(traj)
    assert out.shape == (NUM_ROOT, 4) and np.allclose(out[60], traj[60]) and np.allclose(out[0], traj[0])
    for n in (122, 30):
        with pytest.raises(ValueError, match=rf"traj: expected a window's root states \(\.\.\., 62, 4\).*\({n}, 4\)"):
            interpolated_trajectory(np.zeros((n, 4)))
    with pytest.raises(ValueError, match=r"traj: expected a window's root states"):
        global_motion(np.zeros((61, 3, 3)), np.zeros((61, 4)))
    from graspkit.data.motionfill_dataset import local_motion

    with pytest.raises(ValueError, match=r"traj: expected a window's root states .*got shape \(2, 62, 4\)"):
        local_motion(np.zeros((61, 79, 3)), np.zeros((2, NUM_ROOT, 4)))        # one window, not a batch
    with pytest.raises(ValueError, match=r"markers: expected one window's canonical markers \(61, M, 3\)"):
        local_motion(np.zeros((2, 61, 79, 3)), traj)


@pytest.mark.parametrize("draw, low, floor", [("show_scene", -0.34, 0.0), ("animate", -0.34, 0.0),
                                              ("show_scene", -1.3, -1.3), ("animate", -1.3, -1.3)])
def test_the_floor_grid_is_at_z_0_under_a_body_that_sinks(draw, low, floor):
    """The grid was drawn under the lowest point, so a body 34 cm through the floor looked as if standing on it; a
    scene not set on the floor (a body centred at its pelvis, feet at -1.3 m) keeps the grid under it."""
    import matplotlib.pyplot as plt

    from graspkit import viz
    from graspkit.viz.scene import LAYERS

    box = np.array([[x, y, z] for x in (0, 0.3) for y in (0, 0.3) for z in (low, 0.4)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    if draw == "show_scene":
        fig = viz.show_scene(meshes=[(box, faces)], views=("front",))
    else:
        anim = viz.animate(box[None].repeat(2, 0), faces, views=("front",), max_frames=None, close=False)
        fig = anim._fig
        anim._draw_was_started = True           # not rendered on purpose: matplotlib would warn when it goes
    grids = [c for ax in fig.axes for c in ax.collections if c.get_zorder() == LAYERS["ground"]]
    assert grids and all(np.allclose(np.asarray(s)[:, 2], floor) for g in grids for s in g._segments3d)
    assert min(ax.get_zlim()[0] for ax in fig.axes if hasattr(ax, "get_zlim")) <= low + 1e-9
    plt.close(fig)


def test_saga_warns_for_a_given_start_too_far_for_a_two_second_walk():
    """A Start 3 m away ran at 6 m/s without a word (only start_distance was checked)."""
    from graspkit.data import Start
    from graspkit.saga import synthesize

    kw = dict(grasp_steps=(1, 1, 1), motion_steps=(1, 1), polish_steps=(1, 1), progress=False)
    with pytest.warns(GraspkitWarning, match=r"start: its pelvis is [34]\.\d\d m from the grasp's; covered in"):
        far = synthesize("mug", start=Start(3.0, 0.0, 0.0), **kw)
    assert far.motion.num_frames == 61
