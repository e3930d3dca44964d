"""SAGA evaluation bookkeeping (graspkit.eval_saga): pooled rows, interrupted runs, the tables beside the paper's."""
import json
import shutil

import numpy as np
import pytest
import torch
import trimesh

from graspkit.eval_saga import (PAPER_TAB1, EvalConfig, evaluate, finish_partial, rows_from_objects, summarise,
                                table1, table2)
from graspkit.paths import DATA_STUBS, default_model_path


def _rows(contacts, volumes, depths, floors=None):
    rows = [{"contact": c, "volume_cm3": v, "depth_cm": d} for c, v, d in zip(contacts, volumes, depths)]
    return rows if floors is None else [{**r, "floor_cm": f} for r, f in zip(rows, floors)]


def test_rows_from_objects_pools_bodies_and_averages_apd_over_objects():
    a = _rows([1, 0, 1], [0.5, 0.0, 1.0], [0.1, 0.0, 0.2], [-1.0, 0.5, 2.0])
    b = _rows([1], [3.0], [0.4], [-6.0])
    per = {"mug": {"x": {**summarise(a), "apd": 2.0}}, "camera": {"x": {**summarise(b), "apd": 4.0}}}
    r = rows_from_objects(per)["x"]
    everything = a + b                                             # the pooled mean over all four bodies
    assert r["n"] == 4
    assert r["contact_ratio"] == pytest.approx(np.mean([x["contact"] for x in everything]))
    assert r["volume_cm3"] == pytest.approx(np.mean([x["volume_cm3"] for x in everything]))
    assert r["depth_cm"] == pytest.approx(np.mean([x["depth_cm"] for x in everything]))
    assert r["apd"] == pytest.approx(3.0)
    # the lowest vertex's distance from the floor, whichever side: pooled mean and the largest
    assert r["floor_abs_cm"] == pytest.approx(np.mean([1.0, 0.5, 2.0, 6.0])) and r["floor_max_cm"] == 6.0
    assert "floor_abs_cm" not in rows_from_objects({"mug": {"x": summarise(_rows([1], [0.0], [0.0]))}})["x"]


def test_finish_partial_writes_a_table_with_the_objects_done(tmp_path):
    per = {"mug": {"WholeGrasp w/ opt. (Ours)": {**summarise(_rows([1, 1], [0.2, 0.4], [0.1, 0.1])), "apd": 1.5}}}
    part = tmp_path / "eval.partial.json"
    part.write_text(json.dumps({"config": {"objects": ["mug", "camera"], "placements": 1}, "seconds": 12.0,
                                "per_object": per}))
    res = finish_partial(part, tmp_path / "eval.json")
    assert res["config"]["objects"] == ["mug"] and res["interrupted"]
    assert json.loads((tmp_path / "eval.json").read_text())["rows"] == res["rows"]
    t = table1(res)
    assert "| WholeGrasp w/ opt. (Ours) | 1.50 / 2.92 | 1.00 / 0.94 | 0.30 / 0.48 | 0.10 / 0.16 |" in t
    assert "- / -" in table2(res)                                   # rows not run print as '-'


def test_summarise_apd_is_the_mean_pairwise_marker_distance_per_run():
    import torch

    m = torch.zeros(4, 143, 3)
    m[1, 0, 0] = 3.0                                               # run 1: two sets 3 apart; run 2: identical
    s = summarise(_rows([1] * 4, [0] * 4, [0] * 4), m, per=2)
    assert s["apd"] == pytest.approx((3.0 + 0.0) / 2)
    with pytest.raises(ValueError, match="per: expected the 4 marker sets to come in whole runs of 3"):
        summarise(_rows([1] * 4, [0] * 4, [0] * 4), m, per=3)          # a short last run is not averaged in
    assert set(PAPER_TAB1) >= {"GrabNet-SMPLX", "WholeGrasp w/ opt. (Ours)"}


def test_evaluation_without_the_unshipped_baselines_leaves_their_rows_out(tmp_path, capsys):
    """The baselines' weights are not shipped: a run with only WholeGrasp-VAE evaluates it and the ground truth and
    says which rows are missing and how to make them."""
    shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / "wholegrasp.pt")
    cfg = EvalConfig(objects=("mug",), placements=1, samples=2, gt_grasps=1, steps=(2, 2, 2),
                     polish=(0, 0.0))
    r = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path)
    assert "graspkit train wholegrasp_single" in capsys.readouterr().out
    rows = r["rows"]
    assert not any(k.startswith(("WholeGrasp-single", "GrabNet")) for k in rows)
    assert rows["WholeGrasp w/ opt. (Ours)"]["n"] == 2 and rows["GT + E_cont"]["n"] == 1 and rows["GT mesh"]["n"] == 1
    assert "GrabNet-SMPLX" not in table1(r) and "WholeGrasp w/ opt. (Ours)" in table1(r)
    # the synthetic ground truth stands on the floor z = -t_O of the object frame (its soles within a few mm)
    assert rows["GT mesh"]["floor_abs_cm"] < 0.5, rows["GT mesh"]


def test_grabnet_only_gives_the_full_runs_grabnet_row(tmp_path):
    """`grabnet_only` draws what the full run draws: its GrabNet-SMPLX row equals the full run's (no optimiser
    touches that row), and without the baseline's weights it says which file is missing."""
    import torch

    from graspkit.models.wholegrasp import GRABNET_SMPLX_PATH, GrabNetSMPLX
    from graspkit.train import save_checkpoint

    shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / "wholegrasp.pt")
    cfg = EvalConfig(objects=("mug",), placements=1, samples=3, gt_grasps=1, steps=(2, 2, 2),
                     polish=(0, 0.0))
    with pytest.raises(FileNotFoundError, match=GRABNET_SMPLX_PATH.name):
        evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path, grabnet_only=True)
    torch.manual_seed(0)
    model = GrabNetSMPLX()
    torch.nn.init.normal_(model.dec[-1].weight, std=0.05)       # samples that differ (the zero init gives one body)
    save_checkpoint(tmp_path / GRABNET_SMPLX_PATH.name, model.state())
    full = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path)
    only = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path, grabnet_only=True)
    assert list(only["rows"]) == ["GrabNet-SMPLX"]
    assert only["rows"]["GrabNet-SMPLX"] == full["rows"]["GrabNet-SMPLX"]
    assert only["rows"]["GrabNet-SMPLX"]["apd"] > 0.01


def test_apd_is_taken_within_each_placement():
    """APD is the mean pairwise distance of one placement's samples, averaged over placements (scipy's pdist): two
    placements 5 m apart must not count their distance to each other."""
    import torch
    from scipy.spatial.distance import pdist

    g = torch.Generator().manual_seed(0)
    base = torch.randn(143, 3, generator=g)
    a = base + 0.01 * torch.randn(3, 143, 3, generator=g)
    b = base + 5.0 + 0.02 * torch.randn(3, 143, 3, generator=g)
    rows = [{"contact": 1.0, "volume_cm3": 0.0, "depth_cm": 0.0}] * 6
    want = np.mean([pdist(x.reshape(3, -1).double().numpy()).mean() for x in (a, b)])
    assert summarise(rows, torch.cat([a, b]), per=3)["apd"] == pytest.approx(want, abs=1e-9)


def test_body_rows_measure_each_body_against_its_own_placement():
    """Body i belongs to placement i // per: its floor is at z = -t_O of that placement (object frame), so the
    lowest vertex's height above it is min z + t_O of its own placement."""
    import torch

    from graspkit.body import BodyModel
    from graspkit.eval_saga import Placement, body_rows
    from graspkit.paths import default_model_path

    bm = BodyModel.from_file(default_model_path())
    v = bm.forward_rotmats(torch.eye(3).expand(1, 55, 3, 3), betas=torch.zeros(1, 10), transl=torch.zeros(1, 3)).vertices
    v = v + torch.tensor([3.0, 0.0, 0.0])                                 # far from the object: no contact
    verts = torch.cat([v + torch.tensor([0.0, 0.0, dz]) for dz in (0.0, 0.1, 0.2, 0.3)])
    pls = [Placement("mug", torch.zeros(1, 3), torch.zeros(1, 3), h, torch.eye(3), torch.zeros(143, 3),
                     torch.zeros(143), torch.zeros(1), {}) for h in (0.5, 1.2)]
    rows = body_rows(bm, verts, pls, per=2, refine=1)
    want = [100 * (float(verts[i, :, 2].min()) + (0.5, 1.2)[i // 2]) for i in range(4)]
    np.testing.assert_allclose([r["floor_cm"] for r in rows], want, atol=1e-4)


def test_placements_are_the_grasp_in_the_object_frame():
    """A placement is object-centred in the world orientation: its points lie on the catalogue mesh turned by
    `rotation` (no translation), and its ground-truth markers are SAGA's marker vertices of its ground-truth body
    (the stored parameters, in the same frame), within a few cm of the object."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_markers
    from graspkit.eval_saga import load_placements
    from graspkit.objects import make_object
    from graspkit.rotations import axis_angle_to_matrix

    bm = BodyModel.from_file(default_model_path())
    ids = torch.as_tensor(saga_markers(bm).vertex_ids)
    for name in ("mug", "pitcher"):
        for pl in load_placements(DATA_STUBS / "grasps", name, 2, split=None if name == "pitcher" else "test"):
            mesh = make_object(pl.name)
            mesh.apply_transform(np.block([[pl.rotation.double().numpy(), np.zeros((3, 1))], [np.zeros((1, 3)), 1.0]]))
            _, d, _ = trimesh.proximity.closest_point(mesh, pl.points.double().numpy())
            assert d.max() < 1e-3
            with torch.no_grad():
                v = bm.forward_rotmats(axis_angle_to_matrix(pl.body["fullpose"][None]), betas=pl.body["betas"][None],
                                       transl=pl.body["transl"][None]).vertices[0]
            assert torch.allclose(pl.markers, v[ids].float(), atol=2e-3)
            _, dm, _ = trimesh.proximity.closest_point(mesh, pl.markers.double().numpy())
            assert dm.min() < 0.05


def test_hand_contact_prior_is_the_share_of_grasps_touching_each_vertex():
    """S.3's C_H: per body vertex, the share (0..1) of the split's grasps whose body touches the object there, read
    here from the files with numpy."""
    from graspkit.data.grasp import split_of
    from graspkit.eval_saga import hand_contact_prior

    got = hand_contact_prior(DATA_STUBS / "grasps", split="test").numpy()
    maps = []
    for f in sorted((DATA_STUBS / "grasps").glob("grasp_*.npz")):
        z = np.load(f, allow_pickle=False)
        if split_of(str(z["obj_name"])) == "test" and bool(z["grasp.accepted"]):
            maps.append(z["contact.body"][0].astype(np.float64))
    assert len(maps) >= 2 and np.stack(maps).sum(0).max() >= 2           # some vertex touches in several grasps
    assert np.allclose(got, np.mean(maps, 0), atol=1e-6) and got.max() <= 1.0


def test_table2_puts_ground_truth_and_samples_in_their_columns():
    """SAGA Tab. 2: per stage-3 variant, the fit of the ground-truth markers (GT) and of WholeGrasp-VAE's samples
    (Samples) beside the paper's (E_fit + E_g: contact 0.99 / 0.96, volume 2.21 / 12.20; + E_cont: 0.94 / 0.94,
    0.52 / 0.48), WholeGrasp-single's rows nowhere."""
    from graspkit.eval_saga import table2

    keys = ("GT mesh", "GT + E_fit + E_g", "WholeGrasp w/o opt.", "GT + E_colli", "samples + E_colli", "GT + E_cont",
            "WholeGrasp w/ opt. (Ours)", "WholeGrasp-single w/o opt.")
    rows = {k: {"contact_ratio": 0.11 * (i + 1), "volume_cm3": 1.0 + i, "depth_cm": 0.5 + i} for i, k in enumerate(keys)}
    lines = {x.split("|")[1].strip(): [c.strip() for c in x.split("|")[2:-1]] for x in table2({"rows": rows}).splitlines()[2:]}
    assert lines["E_fit + E_g"] == ["0.22 / 0.99", "0.33 / 0.96", "2.00 / 2.21", "3.00 / 12.20", "1.50 / 0.46",
                                    "2.50 / 0.85"]
    assert lines["+ E_cont"] == ["0.66 / 0.94", "0.77 / 0.94", "6.00 / 0.52", "7.00 / 0.48", "5.50 / 0.17",
                                 "6.50 / 0.16"]
    assert lines["GT mesh"][:2] == ["0.11 / 0.99", "- / -"]


def test_ground_truth_fit_rows_hold_the_ground_truth_bodies_only(tmp_path):
    """Tab. 2's GT rows are the fits of the ground-truth markers (gt_grasps per object), also when WholeGrasp-single's
    weights are there and its samples share the batch (here the shipped WholeGrasp-VAE's weights stand in for them)."""
    import shutil

    from graspkit.eval_saga import EvalConfig, evaluate

    for name in ("wholegrasp.pt", "wholegrasp_single.pt"):
        shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / name)
    cfg = EvalConfig(objects=("mug",), placements=1, samples=2, gt_grasps=1, steps=(2, 2, 2), polish=(0, 0.0))
    rows = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path)["rows"]
    assert rows["WholeGrasp-single w/o opt."]["n"] == 2
    assert [rows[k]["n"] for k in ("GT mesh", "GT + E_fit + E_g", "GT + E_colli", "GT + E_cont")] == [1, 1, 1, 1]
