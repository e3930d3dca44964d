"""Was a motion clip made on this body model? AMASS-layout clips name no body model, but graspkit's own label what the
body that made them did: a foot on the floor at the frames labelled in contact (`contacts`) and, for a reaching clip,
the wrist on the stored goal at the goal frame. Posed on another body the same parameters put the feet under or
above the floor (a body 2 % larger: 1.7-2.0 cm under) and the wrist off the goal; WANDR's clip sets and MotionFill's
windows would learn from that. Grasp and approach files carry GOAL's vertices instead (`grab.body_offset`).

A clip moved along the floor or turned about the vertical (goal moved with it) is the same body's; one raised or sunk
is not, and reads like another body's. Clips without the labels (real AMASS files) are not checked."""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspkit.body.skeleton import JOINT_INDEX

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion

# The body that made graspkit's clips keeps its lowest vertex within 0.25 cm of the floor at every frame labelled in
# contact (the median within 0.05 cm: the 20 shipped clips); one 2 % larger puts the median 1.7-2.0 cm under it.
FLOOR_TOL = 0.01           # m, on the median over the contact frames
# The planner ends within 1 cm of its target or stores the wrist as the goal (`reaching._goal_as_reached`).
GOAL_TOL = 0.02            # m


def clip_offsets(bm: BodyModel, m: Motion) -> dict[str, float]:
    """How clip m sits on bm, for what the clip labels: 'floor' (m, signed), the median over its frames labelled in
    contact of the lowest vertex's height (0 on the body that made it); 'goal' (m), for a reaching clip, the closest
    its wrist comes to the stored target (the goal; for a floor goal FLOOR_WRIST, scaled with the body, above it) on
    the segments from the goal frame to its neighbours (a clip resampled to 30 fps holds the labelled instant between
    two frames). {} for a clip with neither label."""
    out: dict[str, float] = {}
    if m.contacts is not None and m.contacts.any():
        frames = np.flatnonzero(m.contacts.any(1))
        low = []
        for lo in range(0, len(frames), 64):                     # the contact frames in chunks: memory stays bounded
            idx = frames[lo:lo + 64]
            sub = replace(m, poses=m.poses[idx], trans=m.trans[idx], contacts=None, goal=None, goal_frame=None, hand=None)
            low.append(sub.vertices(bm)[..., 2].amin(-1).double())
        out["floor"] = float(torch.cat(low).quantile(0.5))      # (median() takes the lower middle of an even count)
    if m.goal is not None and m.goal_frame is not None and m.hand is not None:
        from graspkit.data.reaching import FLOOR_WRIST
        from graspkit.data.rig import build_rig

        f = int(m.goal_frame)
        lo, hi = max(f - 1, 0), min(f + 2, m.num_frames)
        w = torch.as_tensor(m.slice(lo, hi).joint_positions(bm)[:, JOINT_INDEX[f"{m.hand}_wrist"]], dtype=torch.float64)
        g = np.asarray(m.goal, np.float64)
        target = torch.tensor([g[0], g[1], max(g[2], FLOOR_WRIST * build_rig(bm, m.betas).scale)], dtype=torch.float64)
        t = torch.linspace(0, 1, 11, dtype=torch.float64)[:, None, None]
        between = (1 - t) * w[:-1] + t * w[1:] if len(w) > 1 else w[None]     # (11, frames - 1, 3)
        out["goal"] = float((between - target).norm(dim=-1).min())
    return out


def clip_body_problem(bm: BodyModel, path: str | os.PathLike, kind: str) -> str | None:
    """What is wrong with posing clip file `path` (of folder kind `kind`: locomotion, reach, ...) on bm (a sentence),
    or None when its labels hold on bm (or it has none)."""
    from graspkit.data.formats import load_motion

    off = clip_offsets(bm, load_motion(path))
    said = []
    if abs(off.get("floor", 0.0)) > FLOOR_TOL:
        cm = 100 * off["floor"]
        said.append(f"lowest vertex at the frames labelled in contact lies {abs(cm):.1f} cm "
                    f"{'under' if cm < 0 else 'above'} the floor (on the body that made it: within "
                    f"{100 * FLOOR_TOL:g} cm)")
    if off.get("goal", 0.0) > GOAL_TOL:
        said.append(f"wrist comes no closer than {100 * off['goal']:.1f} cm to the stored goal at the goal frame "
                    "(graspkit's reaching clips end within 1 cm of it on the body that made them; one planned "
                    "towards a goal out of that body's reach, as `plan_reach` keeps it, never gets there)")
    if not said:
        return None
    from graspkit.data.cli import KINDS                      # `graspkit data make`'s clip kinds

    known = kind in KINDS
    return (f"its {kind + ' ' if known else ''}clips do not sit on {bm.source or 'the body model given'} as on the "
            f"body that made them: posed on it, {Path(path).name}'s " + " and its ".join(said)
            + ". Most likely they were made on another body model (GRASPKIT_MODEL names the body; a clip raised or "
            "sunk since it was made reads the same): use the body that made them, or make clips on this one "
            f"(`graspkit data make --kind {kind if known else 'locomotion'} --out DIR`"
            + ("" if known else ", `--kind reach`") + ")")


def check_clips_made_on(bm: BodyModel, paths: Sequence[str | os.PathLike], where: str, kind: str) -> None:
    """ValueError naming `where` when the first of `paths` (motion clips: locomotion, reach, ...) was not made on bm
    (`clip_offsets` past FLOOR_TOL or GOAL_TOL). Clips without graspkit's labels pass; so does an empty list."""
    problem = clip_body_problem(bm, paths[0], kind) if len(paths) else None
    if problem:
        raise ValueError(f"{where}: {problem}")
