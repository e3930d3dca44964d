"""Motion clips made on one body, read with another: `graspkit.data.made_on.clip_offsets` against the smplx package,
and WANDR's clip sets and MotionFill's windows refuse another body's clips (graspkit's own label a foot on the floor
at the frames in contact and the wrist on the goal; real AMASS files label neither and pass)."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from conftest import PROCEDURAL_MODEL, smplx_posed
from graspkit.paths import DATA_STUBS

LOCO = DATA_STUBS / "motion" / "locomotion" / "locomotion_000004.npz"
REACH = DATA_STUBS / "motion" / "reach" / "reach_000006.npz"
RIGHT_WRIST = 21                       # SMPL-X's joint order: pelvis, 21 body joints (..., 20 left, 21 right wrist), ...


def _smplx_offsets(model, m) -> dict[str, float]:
    """clip_offsets' figures by the smplx package: the median over the contact frames of the lowest vertex's height;
    for a reaching clip with its goal above the floor (no FLOOR_WRIST rule), the closest the right wrist comes to it at
    11 points on each segment from the goal frame to a neighbouring frame."""
    frames = np.flatnonzero(m.contacts.any(1))
    v, _ = smplx_posed(model, m.poses[frames], m.trans[frames], m.betas)
    out = {"floor": float(np.median(v[..., 2].min(-1)))}
    if m.goal is not None:
        assert m.hand == "right" and m.goal[2] > 0.3                     # a goal well above the floor
        lo, hi = m.goal_frame - 1, m.goal_frame + 2
        _, j = smplx_posed(model, m.poses[lo:hi], m.trans[lo:hi], m.betas)
        w = j[:, RIGHT_WRIST]
        out["goal"] = min(float(np.linalg.norm((1 - t) * w[k] + t * w[k + 1] - m.goal))
                          for k in range(len(w) - 1) for t in np.linspace(0, 1, 11))
    return out


def test_clip_offsets_are_what_smplx_measures(big):
    """On graspkit's body (which made the stubs) a clip's lowest vertex at the frames labelled in contact is on the
    floor and a reaching clip's wrist on its goal, to a millimetre; on a body 8 % larger the feet sink 6-8 cm and the
    wrist misses the goal by centimetres, as the smplx package poses that body."""
    from graspkit.body import BodyModel
    from graspkit.data import load_motion
    from graspkit.data.made_on import FLOOR_TOL, GOAL_TOL, clip_offsets

    for path in (LOCO, REACH):
        m = load_motion(path)
        for model in (PROCEDURAL_MODEL, big):
            ours, ref = clip_offsets(BodyModel.from_file(model), m), _smplx_offsets(model, m)
            assert ours.keys() == ref.keys() == ({"floor", "goal"} if path == REACH else {"floor"})
            for k in ref:
                assert ours[k] == pytest.approx(ref[k], abs=2e-5), (path.name, model, k)
            if model == PROCEDURAL_MODEL:
                assert abs(ref["floor"]) < FLOOR_TOL / 10 and ref.get("goal", 0.0) < 1e-3
            else:
                assert ref["floor"] < -0.05 and ref.get("goal", 1.0) > GOAL_TOL


def _motion_folder(root, kinds=("locomotion", "reach"), n=3):
    """<root>/<kind>/ with the first n shipped clips of each kind."""
    for kind in kinds:
        (root / kind).mkdir(parents=True)
        for k in range(n):
            shutil.copy(DATA_STUBS / "motion" / kind / f"{kind}_{k:06d}.npz", root / kind)
    return root


def test_readers_refuse_clips_made_on_another_body(big, tmp_path, monkeypatch):
    """WANDR's clip sets (`cached_clips`: `graspkit train wandr`, the clip rows of `eval wandr`) and MotionFill's
    locomotion / reach windows refuse the shipped clips on a body 8 % larger, naming the folder and how far the feet
    are under the floor; on the body that made them they are read; a cache written for one body does not answer for
    the other."""
    from graspkit.body import BodyModel
    from graspkit.data.wandr_dataset import cached_clips, list_clips, load_clips
    from graspkit.eval_motionfill import windows

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    folder = _motion_folder(tmp_path / "motion")
    shipped, other = BodyModel.from_file(PROCEDURAL_MODEL), BodyModel.from_file(big)
    assert len(cached_clips(folder, shipped).names) == 6                       # read, and cached for that body
    with pytest.raises(ValueError, match=rf"folder: {folder / 'locomotion'}: its locomotion clips do not sit on "
                                         r".*SMPLX_NEUTRAL.npz as on the body that made them: posed on it, "
                                         r"locomotion_000000.npz's lowest vertex .* lies [6-8]\.\d cm under the "
                                         r"floor .*made on another body model"):
        cached_clips(folder, other)
    with pytest.raises(ValueError, match=rf"folder: {folder / 'reach'}: its reach clips .* under the floor .* and its "
                                         r"wrist comes no closer than \d\.\d cm to the stored goal"):
        cached_clips(folder, other, kinds=("reach",))
    with pytest.raises(ValueError, match=rf"paths: {folder / 'reach'}: its reach clips do not sit on"):
        load_clips(list_clips(folder, kinds=("reach",)), other)               # the public loader too
    for kind in ("locomotion", "reach"):
        assert set(windows(kind, 2, bm=shipped, data=folder / kind, progress=False)["clip"].tolist()) == {0, 1}
        with pytest.raises(ValueError, match=rf"data: {folder / kind}: its {kind} clips do not sit on"):
            windows(kind, 2, bm=other, data=folder / kind, progress=False)


def test_a_cache_written_before_the_check_answers_no_other_body(big, tmp_path, monkeypatch):
    """Clip sets and windows cached for another body before the check existed (a graspkit of before 2026-12-07) are
    not served: the check runs before the cache is read (an independent review found them served)."""
    from graspkit.body import BodyModel
    from graspkit.data import made_on
    from graspkit.data.wandr_dataset import cached_clips
    from graspkit.eval_motionfill import windows

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    folder = _motion_folder(tmp_path / "motion", n=2)
    other = BodyModel.from_file(big)
    with monkeypatch.context() as m:                                   # the code of before: no check
        m.setattr(made_on, "clip_body_problem", lambda *a: None)
        assert len(cached_clips(folder, other).names) == 4
        assert len(windows("reach", 2, bm=other, data=folder / "reach", progress=False)["clip"]) == 2
    assert len(list((tmp_path / "cache").rglob("*.npz"))) == 2                       # both cached for that body
    with pytest.raises(ValueError, match=r"its locomotion clips do not sit on"):
        cached_clips(folder, other)
    with pytest.raises(ValueError, match=r"its reach clips do not sit on"):
        windows("reach", 2, bm=other, data=folder / "reach", progress=False)


def _turned(m, angle: float, shift: np.ndarray):
    """Clip m turned by `angle` about the vertical through the origin and moved by `shift` (m): poses, translation and
    goal, with the rest pelvis taken from the smplx package (the root turns about it)."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    _, j = smplx_posed(PROCEDURAL_MODEL, np.zeros((1, 55, 3)), np.zeros((1, 3)), m.betas)
    pelvis = j[0, 0]
    turn = Rotation.from_rotvec([0.0, 0.0, angle])
    poses = m.poses.copy()
    poses[:, 0] = (turn * Rotation.from_rotvec(m.poses[:, 0])).as_rotvec()
    trans = turn.apply(m.trans + pelvis) - pelvis + shift
    goal = None if m.goal is None else (turn.apply(m.goal) + shift).astype(np.float32)
    return replace(m, poses=poses, trans=trans.astype(np.float32), goal=goal)


@pytest.mark.parametrize("case", ["turned and moved", "resampled 60", "resampled 20", "raised", "unlabelled"])
def test_clips_moved_on_the_floor_or_resampled_are_their_bodys(case, tmp_path, big):
    """A clip turned about the vertical and moved along the floor (its goal with it), or saved at 60 or 20 fps and
    read back at 30, is still its body's; raised by 3 cm it is refused as another body's would be; a clip without
    graspkit's labels (AMASS's own) is not checked."""
    from dataclasses import replace

    from graspkit.body import BodyModel
    from graspkit.data import load_motion, save_motion
    from graspkit.data.formats import resample
    from graspkit.data.made_on import FLOOR_TOL, GOAL_TOL, check_clips_made_on, clip_offsets

    bm = BodyModel.from_file(PROCEDURAL_MODEL)
    m = load_motion(REACH)
    if case == "turned and moved":
        m = _turned(m, np.radians(130.0), np.array([2.5, -1.0, 0.0]))
    elif case.startswith("resampled"):
        fps = float(case.split()[1])
        poses, trans, contacts, gf = resample(m.poses, m.trans, 30.0, fps, m.contacts, m.goal_frame)
        m = replace(m, poses=poses, trans=trans, contacts=contacts, goal_frame=gf, fps=fps)
    elif case == "raised":
        m = replace(m, trans=m.trans + np.float32([0.0, 0.0, 0.03]))
    else:
        m = replace(m, contacts=None, goal=None, goal_frame=None, hand=None)
    path = save_motion(tmp_path / "reach_000000.npz", m)
    back = load_motion(path)                                       # at 30 fps
    off = clip_offsets(bm, back)
    if case == "unlabelled":
        assert off == {} and clip_offsets(BodyModel.from_file(big), back) == {}
    elif case == "raised":
        assert off["floor"] == pytest.approx(0.03, abs=1e-3)
        with pytest.raises(ValueError, match=r"here: its reach clips .* lies 3\.0 cm above the floor"):
            check_clips_made_on(bm, [path], "here", "reach")
        return
    else:
        assert abs(off["floor"]) < FLOOR_TOL / 5 and off["goal"] < GOAL_TOL / 4, off
    check_clips_made_on(bm, [path], "here", "reach")
