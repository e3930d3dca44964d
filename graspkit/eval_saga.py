"""SAGA's grasp evaluation (§4.1, Tab. 1 and Tab. 2) on graspkit's synthetic grasps, GRAB's six test objects held out.

Protocol (graspkit's, the paper gives no numbers for it): for every test object, the first `placements` accepted
test grasps give object placements (the object's pose of that grasp, object-centred, world orientation, its height
t_O); each model draws `samples` grasps per placement from z ~ N(0, I) (seeded); the bodies are evaluated against
the object mesh in that pose with `graspkit.metrics`:
- APD: mean pairwise L2 distance of the flattened 143 markers of the final bodies, over the samples of one
  placement (SAGA after DLow), averaged over placements;
- contact ratio: share of bodies within GRASP_CONTACT_THRESHOLD = 2 mm of the object (exact signed distance of the
  body vertices; touching or penetrating counts);
- interpenetration volume (cm^3, exact vertical ray casting on a 1 mm grid, the cells along walls refined;
  `--refine 1`: one ray per column, as docs/saga.md's tables) and depth (cm, deepest body vertex).

Tab. 1 rows: GrabNet-SMPLX (SMPL-X parameters sampled directly, no optimisation), WholeGrasp-single without and with
the heuristic optimisation of S.3/S.4, WholeGrasp without and with GraspPose-Opt. "w/o opt." is the fit of the
sampled markers with E_fit + E^g_cont (the paper's footnote says E_fit only, but its Tab. 1 and Tab. 2 give the same
figures for "w/o opt." and "E_fit + E^g_cont", so that is what was run). Tab. 2 rows: stage 3 with E_fit + E^g_cont,
+ E_colli, + E^o_cont on the ground-truth markers (with the ground-truth contact labels) and on sampled markers, and
the ground-truth meshes. Stages 1-2 of Alg. 1 are run once per marker set and shared by its stage-3 variants.
GraspPose-Opt runs with its defaults: the arm joints free on top of the pose prior (`--free-joints none`: Alg. 1's
prior latent alone) and stage 3 run twice, the second time with E^O_colli gated while a hand is sunk, each sample
keeping the lower full energy (where E_colli is on; docs/saga.md).

    python -m graspkit.eval_saga --data ~/.cache/graspkit/grasps/grasp        # prints both tables, writes JSON
"""
from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import Tensor

from graspkit.checks import GraspkitWarning, positive_float, user_stacklevel
from graspkit.cli import (TIME_LIMIT_HELP, check_counts, check_folders, check_out, check_train_out, expand_user_paths,
                          refuse_folder_out, reports_errors)
from graspkit.optim.grasppose import ARM_JOINTS, GraspPoseConfig, GraspPoseWeights
from graspkit.paths import DATA_STUBS, write_json
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.optim.grasppose import GraspObject, GraspPoseOpt, GraspPoseResult

RESULTS_PATH = DATA_STUBS / "checkpoints" / "wholegrasp_eval.json"

# SAGA Tab. 1: APD, contact ratio, interpenetration volume (cm^3), depth (cm)
PAPER_TAB1 = {
    "GrabNet-SMPLX": (0.33, 0.65, 14.15, 0.78),
    "WholeGrasp-single w/o opt.": (2.94, 0.90, 11.44, 0.78),
    "WholeGrasp-single w/ heuristic opt.": (2.94, 0.81, 0.21, 0.12),
    "WholeGrasp w/o opt.": (2.92, 0.96, 12.20, 0.85),
    "WholeGrasp w/ opt. (Ours)": (2.92, 0.94, 0.48, 0.16),
}
# SAGA Tab. 2: (GT, samples) pairs of contact ratio, volume (cm^3), depth (cm); None where the paper has "-"
PAPER_TAB2 = {
    "GT mesh": ((0.99, None), (2.04, None), (0.45, None)),
    "E_fit + E_g": ((0.99, 0.96), (2.21, 12.20), (0.46, 0.85)),
    "+ E_colli": ((0.25, 0.24), (0.12, 0.12), (0.04, 0.07)),
    "+ E_cont": ((0.94, 0.94), (0.52, 0.48), (0.17, 0.16)),
}
VARIANTS = {  # stage-3 settings of GraspPoseConfig
    "fit_g": dict(collision=False, contact=False, ground=True, heuristic=False),
    "fit_g_colli": dict(collision=True, contact=False, ground=True, heuristic=False),
    "full": dict(collision=True, contact=True, ground=True, heuristic=False),
    "heuristic": dict(collision=True, contact=False, ground=True, heuristic=True),
}


@dataclass
class EvalConfig:
    """How much to evaluate (defaults: the run reported in docs/saga.md)."""

    objects: tuple[str, ...] = ("mug", "camera", "toothpaste", "wine_glass", "frying_pan", "binoculars")
    placements: int = 4           # object placements per test object
    samples: int = 10             # grasps drawn per placement and model
    gt_grasps: int = 8            # ground-truth grasps per object for the Tab. 2 GT column
    steps: tuple[int, int, int] = (300, 400, 500)
    seed: int = 0
    threads: int = 1
    free_joints: tuple[str, ...] = ARM_JOINTS   # GraspPoseConfig.free_joints (graspkit's; () is Alg. 1: docs/saga.md)
    restart_sunk: float | None = 0.005  # GraspPoseConfig.restart_sunk (graspkit's; None is Alg. 1's single stage 3)
    stage2_collision: bool = True  # GraspPoseConfig.stage2_collision (graspkit's; False is Alg. 1's E_fit-only stage 2)
    stage2_ground: bool = True     # GraspPoseConfig.stage2_ground (graspkit's; False is Alg. 1's stage 2)
    ground_rest: bool = True       # GraspPoseConfig.ground_rest (graspkit's; False is the paper's |h(v)|)
    floor: float = GraspPoseWeights.floor  # GraspPoseWeights.floor (graspkit's; 0: none, as the paper)
    polish: tuple[int, float] = GraspPoseConfig.polish   # GraspPoseConfig.polish (graspkit's; (0, 0.0) is Alg. 1's)
    refine: int | None = None     # the volume's rays per cell side along walls (None: the default; 1: docs/saga.md's tables)


@dataclass
class Placement:
    """One test object placement: the object in its pose (object frame) and the ground truth grasp there."""

    name: str
    points: Tensor            # (P, 3) object frame (world orientation, centred)
    normals: Tensor
    height: float
    rotation: Tensor          # (3, 3) mesh frame -> object frame
    markers: Tensor           # (143, 3) ground truth
    marker_contact: Tensor    # (143,)
    object_contact: Tensor    # (P,)
    body: dict[str, Tensor]   # ground-truth SMPL-X parameters (object frame): fullpose (55,3) absolute, transl, betas


class NoGraspsError(ValueError):
    """No accepted grasp of an object in a folder (load_placements)."""


PLACEMENT_KEYS = ("obj_name", "object.params.global_orient", "object.params.transl", "object.points", "object.normals",
                  "object.height", "saga.markers", "contact.markers", "contact.object", "body.params.fullpose",
                  "body.params.transl", "body.betas")


def load_placements(root: str | Path, name: str, n: int, split: str = "test") -> list[Placement]:
    """The first n accepted grasps of object `name` (of `split`) in `root` as placements; each file read is checked
    (a ValueError naming it), NoGraspsError when there is none."""
    from graspkit.data.grab import read_arrays
    from graspkit.data.grasp_datasets import check_arrays, grasp_files, moved_since_labels
    from graspkit.rotations import axis_angle_to_matrix

    out = []
    for p in grasp_files(root, "grasp", split=split):
        a = read_arrays(p)
        check_arrays(a, ("obj_name",), p)
        if str(a["obj_name"]) != name:
            continue
        check_arrays(a, PLACEMENT_KEYS + (("goal.object_transl",) if "goal.object_transl" in a else ()), p)
        R = axis_angle_to_matrix(torch.as_tensor(a["object.params.global_orient"][0], dtype=torch.float64)).float()
        t = torch.as_tensor(a["object.params.transl"][0]).float()
        out.append(Placement(
            name, torch.as_tensor(a["object.points"]).float() @ R.T, torch.as_tensor(a["object.normals"]).float() @ R.T,
            float(a["object.height"]), R, torch.as_tensor(a["saga.markers"] + moved_since_labels(a)).float() - t,
            torch.as_tensor(a["contact.markers"][0]).float(), torch.as_tensor(a["contact.object"][0]).float(),
            {"fullpose": torch.as_tensor(a["body.params.fullpose"][0]).float().view(55, 3),
             "transl": torch.as_tensor(a["body.params.transl"][0]).float() - t,
             "betas": torch.as_tensor(a["body.betas"]).float()}))
        if len(out) == n:
            break
    if not out:
        raise NoGraspsError(f"root: no accepted {split} grasps of {name!r} in {root}")
    return out


def hand_contact_prior(root: str | Path, split: str = "train") -> Tensor:
    """S.3's C_H: per body vertex, the share of `split` grasps in which it touches the object (V,)."""
    from graspkit.data.grasp_datasets import grasp_files, read_checked

    files = grasp_files(root, "grasp", split=split)
    if not files:
        raise ValueError(f"root: no {split} grasps in {root}")
    return torch.as_tensor(np.mean([read_checked(p, ("body.params.fullpose", "contact.body"))["contact.body"][0]
                                    for p in files], 0)).float()


def body_rows(bm: BodyModel, vertices: Tensor, placements: list[Placement], per: int,
              refine: int | None = None) -> list[dict[str, float]]:
    """graspkit.metrics.grasp_metrics of bodies (B,V,3) (object frame), `per` consecutive bodies per placement, and
    floor_cm, the lowest vertex's height above the floor z = -t_O (cm; negative below it); `refine`: the volume's
    rays per cell side along walls (None: graspkit.metrics' default; 1: the tables of docs/saga.md)."""
    from graspkit.metrics import grasp_metrics
    from graspkit.objects import make_object

    rows = []
    for i in range(vertices.shape[0]):
        pl = placements[i // per]
        mesh = make_object(pl.name)
        mesh.apply_transform(np.block([[pl.rotation.double().numpy(), np.zeros((3, 1))], [np.zeros((1, 3)), 1.0]]))
        floor = 100 * (float(vertices[i, :, 2].min()) + pl.height)
        rows.append({**grasp_metrics(vertices[i], bm.faces, mesh, refine=refine), "floor_cm": floor})
    return rows


def summarise(rows: list[dict[str, float]], markers: Tensor | None = None, per: int = 1) -> dict[str, float]:
    """Mean contact ratio, volume, depth of metric rows, the mean and largest distance of the lowest vertex from
    the floor (cm); APD over each run of `per` marker sets (B,143,3)."""
    from graspkit.metrics import apd

    out = {"n": len(rows), "contact_ratio": float(np.mean([r["contact"] for r in rows])),
           "volume_cm3": float(np.mean([r["volume_cm3"] for r in rows])),
           "depth_cm": float(np.mean([r["depth_cm"] for r in rows]))}
    if all("floor_cm" in r for r in rows):
        off = np.abs([r["floor_cm"] for r in rows])
        out.update(floor_abs_cm=float(off.mean()), floor_max_cm=float(off.max()))
    if markers is not None and per > 1:
        if len(markers) % per:
            raise ValueError(f"per: expected the {len(markers)} marker sets to come in whole runs of {per} samples, "
                             f"got {len(markers) % per} left over")
        out["apd"] = float(np.mean([apd(markers[i:i + per]) for i in range(0, len(markers), per)]))
    return out


def _object_index(name: str, position: int) -> int:
    """The index that seeds object `name`'s draws: its place in EvalConfig's default objects, else `position`."""
    default = EvalConfig.objects
    return default.index(name) if name in default else position


def _object_batch(placements: list[Placement], per: int, sdf) -> Any:
    """A batched GraspObject: each placement repeated `per` times."""
    from graspkit.optim.grasppose import GraspObject

    rep = lambda xs: torch.stack([x for x in xs for _ in range(per)])  # noqa: E731
    return GraspObject(rep([p.points for p in placements]), rep([p.normals for p in placements]),
                       torch.tensor([p.height for p in placements for _ in range(per)]), sdf,
                       rep([p.rotation for p in placements]))


def _object_subset(obj, idx: Tensor) -> Any:
    """The bodies idx of a batched GraspObject (points, normals, heights, rotations, origins and grids per body)."""
    from graspkit.optim.grasppose import GraspObject

    h = torch.as_tensor(obj.height).reshape(-1)
    return GraspObject(obj.points[idx], obj.normals[idx], h[idx] if h.numel() > 1 else obj.height,
                       [obj.sdf[i] for i in idx.tolist()] if isinstance(obj.sdf, list) else obj.sdf,
                       None if obj.rotation is None else obj.rotation[idx],
                       None if obj.origin is None or obj.origin.dim() == 1 else obj.origin[idx])


def fit_variants(opt: GraspPoseOpt, markers: Tensor, obj: GraspObject, mc: Tensor | None, oc: Tensor | None,
                 variants: list[str], progress: bool = False) -> dict[str, Any]:
    """Alg. 1 stage 1 once, stage 2 once per collision setting (E^B_colli enters stage 2 where the variant has E_colli),
    then stage 3 for each variant from its stage-2 state: {variant: GraspPoseResult}."""
    s1 = opt.fit(markers, obj, mc, oc, progress=progress, stages=(1,))
    bases: dict[bool, Any] = {}
    out = {}
    for v in variants:
        c = VARIANTS[v]["collision"] and opt.cfg.stage2_collision
        if c not in bases:
            bases[c] = opt.with_config(collision=c).fit(markers, obj, mc, oc, progress=progress, init=s1.state,
                                                        stages=(2,))
        base = bases[c]
        out[v] = opt.with_config(**VARIANTS[v]).fit(markers, obj, mc, oc, progress=progress, init=base.state,
                                                    stages=(3,))
        out[v].energies = s1.energies + base.energies + out[v].energies
    return out


@keeps_torch_state
def evaluate(root: str | Path, cfg: EvalConfig | None = None, progress: bool = True,
             out: str | Path | None = RESULTS_PATH, checkpoints: str | Path = DATA_STUBS / "checkpoints",
             grabnet_only: bool = False) -> dict[str, Any]:
    """Run the whole protocol with the models in `checkpoints` (wholegrasp.pt, wholegrasp_single.pt,
    wholegrasp_grabnet_smplx.pt, pose_prior.pt); returns (and writes atomically to `out`, JSON) the summaries.
    `grabnet_only`: only the GrabNet-SMPLX row (no optimisation; the same draws as the full run)."""
    from tqdm.auto import tqdm

    from graspkit.body import BodyModel
    from graspkit.data.grab import check_made_on
    from graspkit.data.grasp_datasets import grasp_files
    from graspkit.data.grasp_io import collision_sdf_grid
    from graspkit.paths import default_model_path
    from graspkit.progress import hidden

    cfg = cfg or EvalConfig()
    torch.set_num_threads(cfg.threads)
    t0 = time.perf_counter()
    bm = BodyModel.from_file(default_model_path())
    check_made_on(bm, grasp_files(root, "grasp", split="test"), f"root: {root}", "grasp")   # the GT rows pose them on bm
    m = _eval_models(bm, cfg, Path(checkpoints), grabnet_only)
    acc: dict[str, dict[str, list]] = {}
    per_object: dict[str, dict[str, dict[str, float]]] = {}
    for oi, name in enumerate(tqdm(cfg.objects, desc="SAGA eval", disable=hidden(progress))):
        pls = load_placements(root, name, max(cfg.placements, cfg.gt_grasps))
        gts, pls = pls[:cfg.gt_grasps], pls[:cfg.placements]

        def add(key: str, rows: list[dict[str, float]], markers: Tensor | None = None, per: int = 1) -> None:
            """Object `name`'s rows (and final markers, `per` a placement, for APD) of table row `key`."""
            acc.setdefault(key, {"rows": [], "apd": []})
            acc[key]["rows"] += rows
            summary = summarise(rows, markers, per)
            if "apd" in summary:
                acc[key]["apd"].append(summary["apd"])
            per_object.setdefault(name, {})[key] = summary

        # seeded by the object's place in the default list, so a run on some objects draws what the full run draws
        g = torch.Generator().manual_seed(cfg.seed * 1000 + _object_index(name, oi))
        draws = _draw(m, pls, cfg.samples, g)
        if grabnet_only:
            add("GrabNet-SMPLX", *_grabnet_rows(bm, m.grabnet, draws["grabnet"], m.pca, pls, cfg.samples, m.ids,
                                                cfg.refine), cfg.samples)
            continue
        _object_rows(bm, m, cfg, pls, gts, draws, collision_sdf_grid(name), add)
        if out is not None:                                # partial results survive an interrupted run
            write_json(Path(out).with_suffix(".partial.json"),
                        {"config": asdict(cfg), "seconds": time.perf_counter() - t0, "per_object": per_object})
    result = {"config": asdict(cfg), "seconds": time.perf_counter() - t0,
              "rows": {k: {**summarise(a["rows"]), **({"apd": float(np.mean(a["apd"]))} if a["apd"] else {})}
                       for k, a in acc.items()},
              "per_object": per_object}
    if out is not None:
        write_json(out, result)
        Path(out).with_suffix(".partial.json").unlink(missing_ok=True)    # only an interrupted run leaves one
    return result


@dataclass
class _EvalModels:
    """What `evaluate` runs: the samplers (WholeGrasp-single and GrabNet-SMPLX None without their weights), the hand
    PCA, the marker vertex ids (143,) and GraspPose-Opt, plain and with the heuristic hand contacts (S.3/S.4)."""
    wg: Any
    single: Any
    grabnet: Any
    pca: Any
    ids: Tensor
    opt: GraspPoseOpt
    opt_h: GraspPoseOpt
    heuristic: bool                                  # WholeGrasp-single's checkpoint holds its hand contact prior


def _eval_models(bm: BodyModel, cfg: EvalConfig, ck: Path, grabnet_only: bool) -> _EvalModels:
    """The models of the checkpoints in folder `ck`; a warning names the baselines whose weights are missing (a
    FileNotFoundError for GrabNet-SMPLX's when grabnet_only)."""
    from graspkit.body.markers import saga_markers
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.models.wholegrasp import (GRABNET_SMPLX_PATH, HandPCA, WholeGraspVAE, load_grabnet_smplx,
                                            load_wholegrasp)
    from graspkit.optim.grasppose import GraspPoseOpt
    from graspkit.train import build_named, load_checkpoint

    ids = torch.as_tensor(saga_markers(bm).vertex_ids)
    prior = load_pose_prior(ck / "pose_prior.pt") if (ck / "pose_prior.pt").is_file() else load_pose_prior()
    wg = load_wholegrasp(ck / "wholegrasp.pt")
    # the baselines are not shipped (size budget): without their weights their rows are left out, not the run
    single_path, grabnet_path = ck / "wholegrasp_single.pt", ck / GRABNET_SMPLX_PATH.name
    single_state = load_checkpoint(single_path) if single_path.is_file() else None
    single = None if single_state is None else build_named(
        single_path, "a WholeGrasp-single checkpoint", lambda: WholeGraspVAE.from_state(single_state))
    grabnet = load_grabnet_smplx(grabnet_path) if grabnet_path.is_file() else None
    missing = [q.name for q, m in ((single_path, single), (grabnet_path, grabnet)) if m is None]
    if grabnet_only and grabnet is None:
        raise FileNotFoundError(f"checkpoints: no {grabnet_path.name} in {ck} (`graspkit train grabnet_smplx`)")
    if missing:
        warnings.warn(f"checkpoints: no {' or '.join(missing)} in {ck} (`graspkit train wholegrasp_single` / "
                      "`graspkit train grabnet_smplx` make them): their rows are left out", GraspkitWarning,
                      stacklevel=user_stacklevel())
    base_cfg = GraspPoseConfig(steps=cfg.steps, free_joints=tuple(cfg.free_joints), restart_sunk=cfg.restart_sunk,
                               stage2_collision=cfg.stage2_collision, stage2_ground=cfg.stage2_ground,
                               ground_rest=cfg.ground_rest, polish=tuple(cfg.polish),
                               weights=GraspPoseWeights(floor=cfg.floor))
    opt = GraspPoseOpt(bm, prior, base_cfg)
    ch = None if single_state is None else single_state.get("hand_contact_prior")
    opt_h = GraspPoseOpt(bm, prior, base_cfg, hand_contact_prior=None if ch is None else ch.float()[opt.hand_ids])
    return _EvalModels(wg, single, grabnet, HandPCA(bm), ids, opt, opt_h, ch is not None)


def _draw(m: _EvalModels, pls: list[Placement], n: int, g: torch.Generator) -> dict[str, Any]:
    """n draws per placement from each sampler, in this order from `g`: WholeGrasp's markers (N,143,3) and contacts
    (N,143), (N,2048), WholeGrasp-single's markers (N or 0,143,3), GrabNet-SMPLX's parameters (N, n_params) or
    None; N = len(pls) * n."""
    s = [m.wg.sample(p.points, p.normals, p.height, n, g, centre=torch.zeros(3)) for p in pls]
    mk, mc, oc = (torch.cat([getattr(x, k) for x in s]) for k in ("markers", "marker_contact", "object_contact"))
    mk1 = mk[:0] if m.single is None else torch.cat(
        [m.single.sample(p.points, p.normals, p.height, n, g, centre=torch.zeros(3)).markers for p in pls])
    x = None if m.grabnet is None else torch.cat([m.grabnet.sample(p.points, p.normals, p.height, n, g) for p in pls])
    return {"markers": mk, "marker_contact": mc, "object_contact": oc, "single": mk1, "grabnet": x}


def _object_rows(bm: BodyModel, m: _EvalModels, cfg: EvalConfig, pls: list[Placement], gts: list[Placement],
                 draws: dict[str, Any], sdf: Any, add: Callable[..., None]) -> None:
    """Every row of one object: the draws and the ground-truth markers optimised in one batch, the bodies measured,
    each row's metric rows given to add(key, rows, markers=None, per=1)."""
    n = cfg.samples
    mk, mk1 = draws["markers"], draws["single"]
    # one batch per object: WholeGrasp samples | WholeGrasp-single samples | ground-truth markers. The samples
    # are independent (Adam is per parameter), so Alg. 1's stages 1-2 run once for all of them, and each stage-3
    # variant once for the marker sets it applies to (2,700 steps per object instead of 6,100)
    nw = len(pls) * n
    n1 = len(mk1)                                              # 0 without WholeGrasp-single
    places = [p for p in pls for _ in range(n)] * (2 if n1 else 1) + gts
    B = len(places)
    iw, i1, ig = torch.arange(nw), torch.arange(nw, nw + n1), torch.arange(nw + n1, B)
    obj = _object_batch(places, 1, sdf)
    markers = torch.cat([mk, mk1, torch.stack([p.markers for p in gts])])
    # stage 2 twice from one stage 1: without E_colli (the rows without it) and with (GraspPoseConfig's
    # stage2_collision: the rows with E_colli in stage 3 have it in stage 2 too)
    opt = m.opt
    s1 = opt.fit(markers, obj, progress=False, stages=(1,))
    bases = {c: opt.with_config(collision=c).fit(markers, obj, progress=False, init=s1.state, stages=(2,))
             for c in ((False, True) if opt.cfg.stage2_collision else (False,))}

    def stage3(o: GraspPoseOpt, idx: Tensor, variant: str, cm: Tensor | None = None,
               co: Tensor | None = None) -> GraspPoseResult:
        """Stage 3 of one variant for the bodies idx of the batch, from the shared stages 1-2."""
        base = bases[VARIANTS[variant]["collision"] and opt.cfg.stage2_collision]
        return o.with_config(**VARIANTS[variant]).fit(
            markers[idx], _object_subset(obj, idx), cm, co, progress=False,
            init={k: v[idx] for k, v in base.state.items()}, stages=(3,))

    wg_gt = torch.cat([iw, ig])
    cm = torch.cat([draws["marker_contact"], torch.stack([p.marker_contact for p in gts])])
    co = torch.cat([draws["object_contact"], torch.stack([p.object_contact for p in gts])])
    res = {"fit_g": stage3(opt, torch.arange(B), "fit_g"), "fit_g_colli": stage3(opt, wg_gt, "fit_g_colli"),
           "full": stage3(opt, wg_gt, "full", cm, co)}
    rows = {v: body_rows(bm, r.vertices, [places[i] for i in (range(B) if v == "fit_g" else wg_gt)], 1,
                       cfg.refine)
            for v, r in res.items()}
    for v, key in (("fit_g", "WholeGrasp w/o opt."), ("fit_g_colli", "samples + E_colli"),
                   ("full", "WholeGrasp w/ opt. (Ours)")):
        add(key, rows[v][:nw], res[v].markers[:nw], n)
    # WholeGrasp-single: E_fit + E_g, and the heuristic optimisation (S.3/S.4)
    if n1:
        add("WholeGrasp-single w/o opt.", rows["fit_g"][nw:nw + n1], res["fit_g"].markers[nw:nw + n1], n)
    if n1 and m.heuristic:
        r = stage3(m.opt_h, i1, "heuristic")
        add("WholeGrasp-single w/ heuristic opt.", body_rows(bm, r.vertices, places[nw:nw + n1], 1, cfg.refine),
            r.markers, n)
    if draws["grabnet"] is not None:                      # GrabNet-SMPLX: parameters sampled directly
        add("GrabNet-SMPLX", *_grabnet_rows(bm, m.grabnet, draws["grabnet"], m.pca, pls, n, m.ids, cfg.refine), n)
    # ground truth: meshes, and its markers fitted with the three stage-3 variants (ground-truth contacts)
    fp = torch.stack([p.body["fullpose"] for p in gts])
    with torch.no_grad():
        vg = bm.forward_rotmats(_absolute_rotmats(fp), betas=torch.stack([p.body["betas"] for p in gts]),
                                transl=torch.stack([p.body["transl"] for p in gts])).vertices
    add("GT mesh", body_rows(bm, vg, gts, 1, cfg.refine))
    add("GT + E_fit + E_g", rows["fit_g"][nw + n1:])
    add("GT + E_colli", rows["fit_g_colli"][nw:])
    add("GT + E_cont", rows["full"][nw:])


def _grabnet_rows(bm, grabnet, x: Tensor, pca, pls: list[Placement], n: int, ids: Tensor,
                  refine: int | None) -> tuple[list[dict[str, float]], Tensor]:
    """Metric rows and markers (B,143,3) of GrabNet-SMPLX's parameter samples x (B, n_params), n per placement."""
    rot, betas, transl = grabnet.to_rotmats(x, pca)
    with torch.no_grad():
        v = bm.forward_rotmats(rot, betas=betas, transl=transl).vertices
    return body_rows(bm, v, pls, n, refine), v[:, ids]


def rows_from_objects(per_object: dict[str, dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Table rows from per-object summaries: metrics averaged over all bodies (weighted by n), APD over objects
    (the same figures `evaluate` gives; also turns the partial file of an interrupted run into a table)."""
    rows: dict[str, dict[str, float]] = {}
    keys = list(dict.fromkeys(k for o in per_object.values() for k in o))
    for k in keys:
        parts = [o[k] for o in per_object.values() if k in o]
        n = sum(r["n"] for r in parts)
        rows[k] = {"n": n, **{m: float(sum(r[m] * r["n"] for r in parts) / n)
                              for m in ("contact_ratio", "volume_cm3", "depth_cm", "floor_abs_cm")
                              if all(m in r for r in parts)}}
        if all("floor_max_cm" in r for r in parts):
            rows[k]["floor_max_cm"] = max(r["floor_max_cm"] for r in parts)
        apds = [r["apd"] for r in parts if "apd" in r]
        if apds:
            rows[k]["apd"] = float(np.mean(apds))
    return rows


def finish_partial(partial: str | Path, out: str | Path = RESULTS_PATH) -> dict[str, Any]:
    """The result of an interrupted `evaluate` from its .partial.json (config narrowed to the objects done)."""
    partial = Path(partial)
    if not partial.is_file():
        raise FileNotFoundError(f"partial: no file {partial} (expected the .partial.json an interrupted run leaves)")
    try:
        part = json.loads(partial.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"partial: {partial} is not JSON ({e})") from None
    if not isinstance(part, dict) or not {"config", "per_object"} <= set(part):
        raise ValueError(f"partial: {partial} has no 'config' and 'per_object' (expected an interrupted run's "
                         ".partial.json)")
    _check_per_object(part["config"], part["per_object"], partial)
    cfg = dict(part["config"], objects=list(part["per_object"]))
    result = {"config": cfg, "seconds": part.get("seconds"), "rows": rows_from_objects(part["per_object"]),
              "per_object": part["per_object"], "interrupted": True}
    write_json(out, result)
    return result


def _check_per_object(config: Any, per_object: Any, path: Path) -> None:
    """ValueError naming `path` unless config is a dict and per_object maps objects to rows {method: {'n': count >= 1,
    and the numbers table1 reads}}, as `evaluate` writes them."""
    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    if not isinstance(config, dict):
        raise ValueError(f"partial: {path}: 'config' is a {type(config).__name__}, expected an object")
    if not isinstance(per_object, dict):
        raise ValueError(f"partial: {path}: 'per_object' is a {type(per_object).__name__}, expected an object")
    for obj, rows in per_object.items():
        for method, r in (rows.items() if isinstance(rows, dict) else [("?", rows)]):
            ok = isinstance(r, dict) and isinstance(r.get("n"), int) and r["n"] >= 1 and all(
                number(r.get(m)) for m in ("contact_ratio", "volume_cm3", "depth_cm"))
            if not ok:
                raise ValueError(f"partial: {path}: the row of {method!r} on {obj!r} is not one `evaluate` writes "
                                 "(expected n >= 1 and the numbers contact_ratio, volume_cm3, depth_cm)")


def _absolute_rotmats(fullpose: Tensor) -> Tensor:
    """(B,55,3) absolute axis-angle -> (B,55,3,3)."""
    from graspkit.rotations import axis_angle_to_matrix

    return axis_angle_to_matrix(fullpose)


def load_results(path: str | Path = RESULTS_PATH) -> dict[str, Any]:
    """The stored evaluation (JSON written by `evaluate`)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no evaluation results at {path} (run python -m graspkit.eval_saga)")
    try:
        doc = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"path: {path} is not JSON ({e})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("rows"), dict) or not doc["rows"]:
        raise ValueError(f"path: {path} is not a SAGA evaluation (expected an object with the 'rows' "
                         "`python -m graspkit.eval_saga` writes)")
    return doc


def _fmt(x: float | None, nd: int = 2) -> str:
    return "-" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{nd}f}"


def table1(result: dict[str, Any]) -> str:
    """SAGA Tab. 1, ours beside the paper's: APD, contact ratio, volume (cm^3), depth (cm)."""
    lines = ["| method | APD ours / paper | contact ratio ours / paper | volume cm³ ours / paper | depth cm ours / paper |",
             "|---|---|---|---|---|"]
    for key, paper in PAPER_TAB1.items():
        r = result["rows"].get(key)
        if r is None:
            continue
        ours = (r.get("apd"), r["contact_ratio"], r["volume_cm3"], r["depth_cm"])
        lines.append(f"| {key} | " + " | ".join(f"{_fmt(o)} / {_fmt(p)}" for o, p in zip(ours, paper)) + " |")
    return "\n".join(lines)


def table2(result: dict[str, Any]) -> str:
    """SAGA Tab. 2, ours beside the paper's: contact ratio, volume, depth on ground-truth and sampled markers."""
    keys = {"GT mesh": ("GT mesh", None), "E_fit + E_g": ("GT + E_fit + E_g", "WholeGrasp w/o opt."),
            "+ E_colli": ("GT + E_colli", "samples + E_colli"), "+ E_cont": ("GT + E_cont", "WholeGrasp w/ opt. (Ours)")}
    lines = ["| stage-3 terms | contact GT | contact samples | volume GT | volume samples | depth GT | depth samples |",
             "|---|---|---|---|---|---|---|"]
    for name, (gk, sk) in keys.items():
        g, s = result["rows"].get(gk), result["rows"].get(sk) if sk else None
        paper = PAPER_TAB2[name]
        cells = []
        for m, (pg, ps) in zip(("contact_ratio", "volume_cm3", "depth_cm"), paper):
            cells.append(f"{_fmt(g[m] if g else None)} / {_fmt(pg)}")
            cells.append(f"{_fmt(s[m] if s else None)} / {_fmt(ps)}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


@reports_errors("python -m graspkit.eval_saga")
def main(argv: list[str] | None = None) -> int:
    """Command line: run the evaluation and print both tables."""
    ap = argparse.ArgumentParser(prog="python -m graspkit.eval_saga", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="folder with grasp_*.npz (graspkit data make --kind grasp)")
    ap.add_argument("--out", type=Path, default=RESULTS_PATH)
    ap.add_argument("--placements", type=int, default=EvalConfig.placements)
    ap.add_argument("--samples", type=int, default=EvalConfig.samples)
    ap.add_argument("--gt", type=int, default=EvalConfig.gt_grasps)
    ap.add_argument("--objects", nargs="*", default=None)
    ap.add_argument("--checkpoints", type=Path, default=DATA_STUBS / "checkpoints")
    ap.add_argument("--steps", type=int, nargs=3, default=EvalConfig.steps)
    ap.add_argument("--free-joints", nargs="*", default=["arms"], metavar="JOINT",
                    help="body joints given a free rotation on top of the pose prior in stages 2-3 ('arms', the "
                         "default: the collars, shoulders, elbows and wrists; 'none': Alg. 1's prior latent alone)")
    ap.add_argument("--no-restart", action="store_true",
                    help="stage 3 once, as Alg. 1 (default: a second, gated run per sample, the lower energy kept)")
    ap.add_argument("--refine", type=int, default=None,
                    help="the volume's rays per cell side along walls (default: graspkit.metrics'; 1: the docs' tables)")
    ap.add_argument("--no-stage2-collision", action="store_true",
                    help="stage 2 without E^B_colli, as Alg. 1 (default: E^B_colli too where stage 3 has E_colli)")
    ap.add_argument("--no-stage2-ground", action="store_true",
                    help="stage 2 without E_g, as Alg. 1 (default: E_g too, the feet held to the floor)")
    ap.add_argument("--no-ground-rest", action="store_true",
                    help="E_g as the paper's |h(v)| (default: each sole vertex's height less its height at rest)")
    ap.add_argument("--no-floor", action="store_true",
                    help="no floor term (default: the lowest sole vertex held above the floor, graspkit's)")
    ap.add_argument("--grabnet-only", action="store_true",
                    help="only the GrabNet-SMPLX row (no optimisation; the same draws as the full run)")
    ap.add_argument("--finish", type=Path, default=None, help="only turn this .partial.json into --out and print it")
    args = ap.parse_args(argv)
    refuse_folder_out(argv)
    expand_user_paths(args)
    check_counts(args, placements=1, samples=1, gt=1, refine=1)
    check_train_out(args.out)                         # its default is in data_stubs/: none in a plain `pip install`
    check_out(args.out, is_file=True)                 # before any work (the partial results are written beside it)
    if any(s < 0 for s in args.steps):
        raise ValueError(f"--steps: expected three step counts >= 0, got {args.steps}")
    if args.finish is not None:
        res = finish_partial(args.finish, args.out)
        print(table1(res), table2(res), sep="\n\n")
        return 0
    if args.data is None:
        ap.error("--data: the folder of grasp_*.npz is required (unless --finish)")
    check_folders(args.data)
    from graspkit.data.grasp import SPLITS
    from graspkit.optim.grasppose import expand_free_joints

    odd = [o for o in args.objects or () if o not in SPLITS["test"]]
    if odd:
        raise ValueError(f"--objects: {odd[0]!r} is not one of the held-out test objects the evaluation reads, "
                         f"expected some of {list(SPLITS['test'])}")

    cfg = EvalConfig(placements=args.placements, samples=args.samples, gt_grasps=args.gt, steps=tuple(args.steps),
                     free_joints=expand_free_joints(args.free_joints),
                     restart_sunk=None if args.no_restart else EvalConfig.restart_sunk,
                     stage2_collision=not args.no_stage2_collision, stage2_ground=not args.no_stage2_ground,
                     ground_rest=not args.no_ground_rest, floor=0.0 if args.no_floor else EvalConfig.floor,
                     refine=args.refine)
    if args.objects:
        cfg = replace(cfg, objects=tuple(args.objects))
    res = evaluate(args.data, cfg, out=args.out, checkpoints=args.checkpoints, grabnet_only=args.grabnet_only)
    print(table1(res))
    print()
    print(table2(res))
    print(f"\n{res['seconds']:.0f} s; written to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


# ------------------------------------------------------------------------------------------------ `graspkit train`
def add_saga_train_commands(train_sub: argparse._SubParsersAction) -> None:
    """`graspkit train {wholegrasp,wholegrasp_single,grabnet_smplx,pose_prior}` (subcommands of `graspkit train`)."""
    from graspkit.paths import cache_dir

    default = cache_dir() / "grasps" / "grasp"
    helps = {"wholegrasp": "SAGA's WholeGrasp-VAE (§3.2)", "wholegrasp_single": "WholeGrasp-single (App. B.1)",
             "grabnet_smplx": "the GrabNet-SMPLX baseline (App. B.1)",
             "pose_prior": "the body-pose prior GraspPose-Opt uses in place of VPoser"}
    for name, text in helps.items():
        p = train_sub.add_parser(name, help=f"train {text}")
        if name == "pose_prior":
            p.add_argument("--data", type=Path, default=None,
                           help="folder of grasp_*.npz whose training poses join the clips' (default: none)")
        else:
            p.add_argument("--data", type=Path, default=default, help=f"folder of grasp_*.npz (default {default})")
        out = "wholegrasp_grabnet_smplx.pt" if name == "grabnet_smplx" else f"{name}.pt"
        p.add_argument("--out", type=Path, default=None, help=f"weights (default data_stubs/checkpoints/{out})")
        p.set_defaults(out_is_file=True)
        p.add_argument("--epochs", type=int, default=30 if name == "pose_prior" else 12)
        p.add_argument("--time-limit", type=positive_float, default=None if name == "pose_prior" else 600.0,
                       help=TIME_LIMIT_HELP + (" (default: none)" if name == "pose_prior" else " (default 600)"))
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--threads", type=int, default=1)
        if name == "wholegrasp":
            p.add_argument("--consistency", choices=("paper", "signed"), default="paper",
                           help="Eq. 3's distances: as printed (default) or signed Euclidean (the authors' code)")
        if name == "grabnet_smplx":
            p.add_argument("--body-space", choices=("prior", "rot6d"), default="prior",
                           help="the body pose as the pose prior's 32-D latent (SAGA's theta_b, default) or 21 x 6D")
        p.set_defaults(func=lambda a, name=name: _cmd_train(a, name))


def _cmd_train(args: argparse.Namespace, name: str) -> int:
    """Run one SAGA training command and print where the weights went and the validation figures."""
    from graspkit.models import wholegrasp as W

    torch.set_num_threads(args.threads)
    if name == "pose_prior":
        from graspkit.data.grasp_datasets import grasp_files
        from graspkit.models.pose_prior import (POSE_PRIOR_PATH, angle_error, heldout_clip_poses, load_pose_prior,
                                                pose_training_set, train_pose_prior)

        extra = None
        if args.data:                                # grasp poses, repeated 4x: ~900 grasps beside ~15k clip frames
            if not Path(args.data).is_dir():
                raise ValueError(f"--data: no such folder {args.data} (grasps of `graspkit data make --kind grasp`)")
            extra = np.tile(grasp_body_poses(args.data, split="train"), (4, 1, 1))
        t0 = time.perf_counter()
        hist = train_pose_prior(args.out or POSE_PRIOR_PATH, pose_training_set(200, args.seed, extra=extra),
                                epochs=args.epochs, seed=args.seed, time_limit_s=args.time_limit)
        # the logged "val" rows are a row split of the tiled, mirrored array (copies of training rows among them):
        # the held-out figures are on clips of another seed stream and on the validation objects' grasps
        prior = load_pose_prior(args.out or POSE_PRIOR_PATH)
        held = f"held-out clips {angle_error(prior, heldout_clip_poses(100, args.seed)):.2f}"
        if args.data and grasp_files(args.data, "grasp", split="val"):
            val = grasp_body_poses(args.data, split="val")
            held += f", validation-object grasps {angle_error(prior, val):.2f} ({len(val)})"
        print(f"wrote {args.out or POSE_PRIOR_PATH}: {len(hist)} epochs in {time.perf_counter() - t0:.0f} s; joint "
              f"angle error (deg): row split {hist[-1]['val_angle_error_deg']:.2f}, {held}")
        return 0
    if name == "grabnet_smplx":
        info = W.train_grabnet_smplx(args.data, args.out, epochs=args.epochs, seed=args.seed,
                                     time_limit_s=args.time_limit, threads=args.threads, body_space=args.body_space)
    else:
        info = W.train_wholegrasp(args.data, args.out, multitask=name == "wholegrasp", epochs=args.epochs,
                                  seed=args.seed, time_limit_s=args.time_limit, threads=args.threads,
                                  **({"consistency": args.consistency} if name == "wholegrasp" else {}))
    print(f"wrote {info['out']}: {len(info['history'])} epochs in {info['seconds']:.0f} s; "
          f"val {json.dumps(info.get('val', {}))}")
    return 0


def grasp_body_poses(root: str | Path, split: str = "train") -> np.ndarray:
    """Body poses (n, 21, 3) of the grasps of one split (extra training poses for the pose prior)."""
    from graspkit.data.grasp_datasets import grasp_files, read_checked

    files = grasp_files(root, "grasp", split=split)
    if not files:
        raise ValueError(f"--data: no grasp files of the {split} split in {root} (expected grasp_*.npz, made by "
                         "`graspkit data make --kind grasp`)")
    keys = ("body.params.fullpose", "body.params.body_pose")
    return np.stack([read_checked(p, keys)["body.params.body_pose"][0].reshape(21, 3) for p in files]).astype(np.float32)


# ------------------------------------------------------------------------------------------------ lesson examples
EXAMPLES_PATH = DATA_STUBS / "checkpoints" / "wholegrasp_examples.pt"


def save_examples(root: str | Path, path: str | Path = EXAMPLES_PATH, per_object: int = 4,
                  split: str = "val") -> Path:
    """A few grasps of one split (placements, float16, weights-only) for the lesson: `per_object` per object."""
    from graspkit.data.grasp import SPLITS
    from graspkit.train import save_checkpoint

    items: dict[str, list] = {}
    for name in SPLITS[split]:
        try:
            found = load_placements(root, name, per_object, split)
        except NoGraspsError:
            continue                                     # no grasp of this object in the folder
        for p in found:
            row = {"points": p.points, "normals": p.normals, "height": torch.tensor(p.height),
                   "rotation": p.rotation, "markers": p.markers, "marker_contact": p.marker_contact,
                   "object_contact": p.object_contact, **p.body}
            for k, v in row.items():
                items.setdefault(k, []).append(v)
            items.setdefault("names", []).append(name)
    if not items:
        raise ValueError(f"root: no {split} grasps in {root}")
    state = {k: (torch.stack(v).half() if k not in ("names", "rotation") else
                 (torch.stack(v) if k == "rotation" else list(v))) for k, v in items.items()}
    return save_checkpoint(path, state)


def load_examples(path: str | Path = EXAMPLES_PATH) -> list[Placement]:
    """The lesson's example grasps as Placements."""
    from graspkit.train import load_checkpoint

    s = load_checkpoint(path)
    keys = ("names", "points", "normals", "height", "rotation", "markers", "marker_contact", "object_contact",
            "fullpose", "transl", "betas")
    missing = [k for k in keys if k not in s]
    if missing:
        raise ValueError(f"path: {path} is not a lesson-examples checkpoint of save_examples (no {missing[0]!r})")
    return [Placement(n, s["points"][i].float(), s["normals"][i].float(), float(s["height"][i]),
                      s["rotation"][i].float(), s["markers"][i].float(), s["marker_contact"][i].float(),
                      s["object_contact"][i].float(),
                      {"fullpose": s["fullpose"][i].float(), "transl": s["transl"][i].float(),
                       "betas": s["betas"][i].float()})
            for i, n in enumerate(s["names"])]
