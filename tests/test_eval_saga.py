"""SAGA evaluation bookkeeping (graspkit.eval_saga): pooled rows, interrupted runs, the tables beside the paper's."""
import json
import shutil
from typing import Any

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.distance import pdist

import graspkit.eval_saga as ES
from graspkit.eval_saga import (PAPER_TAB1, EvalConfig, evaluate, finish_partial, load_placements, rows_from_objects,
                                summarise, table1, table2)
from graspkit.paths import DATA_STUBS, default_model_path

# the baselines' weights are not shipped: most runs here go without them, and evaluate says so in a warning
pytestmark = pytest.mark.filterwarnings("ignore:checkpoints. no .* their rows are left out:UserWarning")


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
    m = torch.zeros(4, 143, 3)
    m[1, 0, 0] = 3.0                                               # run 1: two sets 3 apart; run 2: identical
    s = summarise(_rows([1] * 4, [0] * 4, [0] * 4), m, per=2)
    assert s["apd"] == pytest.approx((3.0 + 0.0) / 2)
    with pytest.raises(ValueError, match="per: expected the 4 marker sets to come in whole runs of 3"):
        summarise(_rows([1] * 4, [0] * 4, [0] * 4), m, per=3)          # a short last run is not averaged in
    assert set(PAPER_TAB1) >= {"GrabNet-SMPLX", "WholeGrasp w/ opt. (Ours)"}


def test_evaluation_without_the_unshipped_baselines_leaves_their_rows_out(tmp_path, capsys):
    """The baselines' weights are not shipped: a run with only WholeGrasp-VAE evaluates it and the ground truth and
    says which rows are missing and how to make them, as a warning (it had been printed into the table's stdout)."""
    shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / "wholegrasp.pt")
    cfg = EvalConfig(objects=("mug",), placements=1, samples=2, gt_grasps=1, steps=(2, 2, 2),
                     polish=(0, 0.0))
    with pytest.warns(UserWarning, match="graspkit train wholegrasp_single"):
        r = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=tmp_path / "e.json", checkpoints=tmp_path)
    assert capsys.readouterr().out == ""
    # a run that finished leaves its table and not the .partial.json an interrupted one leaves (it did, a check found)
    assert (tmp_path / "e.json").is_file() and not (tmp_path / "e.partial.json").exists()
    rows = r["rows"]
    assert not any(k.startswith(("WholeGrasp-single", "GrabNet")) for k in rows)
    assert rows["WholeGrasp w/ opt. (Ours)"]["n"] == 2 and rows["GT + E_cont"]["n"] == 1 and rows["GT mesh"]["n"] == 1
    assert "GrabNet-SMPLX" not in table1(r) and "WholeGrasp w/ opt. (Ours)" in table1(r)
    # the synthetic ground truth stands on the floor z = -t_O of the object frame (its soles within a few mm)
    assert rows["GT mesh"]["floor_abs_cm"] < 0.5, rows["GT mesh"]


def test_grabnet_only_gives_the_full_runs_grabnet_row(tmp_path):
    """`grabnet_only` draws what the full run draws: its GrabNet-SMPLX row equals the full run's (no optimiser
    touches that row), and without the baseline's weights it says which file is missing."""
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
    from graspkit.body import BodyModel
    from graspkit.eval_saga import Placement, body_rows

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


@pytest.mark.parametrize("split", ["test", None])
def test_hand_contact_prior_is_the_share_of_grasps_touching_each_vertex(split):
    """S.3's C_H: per body vertex, the share (0..1) of the split's grasps whose body touches the object there, read
    here from the files with numpy; learnt from the training grasps unless a split is given."""
    from graspkit.data.grasp import split_of
    from graspkit.eval_saga import hand_contact_prior

    got = (hand_contact_prior(DATA_STUBS / "grasps") if split is None else
           hand_contact_prior(DATA_STUBS / "grasps", split=split)).numpy()
    maps = []
    for f in sorted((DATA_STUBS / "grasps").glob("grasp_*.npz")):
        with np.load(f, allow_pickle=False) as z:
            if split_of(str(z["obj_name"])) == (split or "train") and bool(z["grasp.accepted"]):
                maps.append(z["contact.body"][0].astype(np.float64))
    assert len(maps) >= 2 and np.stack(maps).sum(0).max() >= 2           # some vertex touches in several grasps
    assert np.allclose(got, np.mean(maps, 0), atol=1e-6) and got.max() <= 1.0


def test_table2_puts_ground_truth_and_samples_in_their_columns():
    """SAGA Tab. 2: per stage-3 variant, the fit of the ground-truth markers (GT) and of WholeGrasp-VAE's samples
    (Samples) beside the paper's (E_fit + E_g: contact 0.99 / 0.96, volume 2.21 / 12.20; + E_colli: 0.25 / 0.24,
    0.12 / 0.12; + E_cont: 0.94 / 0.94, 0.52 / 0.48), WholeGrasp-single's rows nowhere."""
    keys = ("GT mesh", "GT + E_fit + E_g", "WholeGrasp w/o opt.", "GT + E_colli", "samples + E_colli", "GT + E_cont",
            "WholeGrasp w/ opt. (Ours)", "WholeGrasp-single w/o opt.")
    rows = {k: {"contact_ratio": 0.11 * (i + 1), "volume_cm3": 1.0 + i, "depth_cm": 0.5 + i} for i, k in enumerate(keys)}
    lines = {x.split("|")[1].strip(): [c.strip() for c in x.split("|")[2:-1]] for x in table2({"rows": rows}).splitlines()[2:]}
    assert lines["E_fit + E_g"] == ["0.22 / 0.99", "0.33 / 0.96", "2.00 / 2.21", "3.00 / 12.20", "1.50 / 0.46",
                                    "2.50 / 0.85"]
    assert lines["+ E_colli"] == ["0.44 / 0.25", "0.55 / 0.24", "4.00 / 0.12", "5.00 / 0.12", "3.50 / 0.04",
                                  "4.50 / 0.07"]
    assert lines["+ E_cont"] == ["0.66 / 0.94", "0.77 / 0.94", "6.00 / 0.52", "7.00 / 0.48", "5.50 / 0.17",
                                 "6.50 / 0.16"]
    assert lines["GT mesh"][:2] == ["0.11 / 0.99", "- / -"]


def test_ground_truth_fit_rows_hold_the_ground_truth_bodies_only(tmp_path):
    """Tab. 2's GT rows are the fits of the ground-truth markers (gt_grasps per object), also when WholeGrasp-single's
    weights are there and its samples share the batch (here the shipped WholeGrasp-VAE's weights stand in for them)."""
    for name in ("wholegrasp.pt", "wholegrasp_single.pt"):
        shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / name)
    cfg = EvalConfig(objects=("mug",), placements=1, samples=2, gt_grasps=1, steps=(2, 2, 2), polish=(0, 0.0))
    rows = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path)["rows"]
    assert rows["WholeGrasp-single w/o opt."]["n"] == 2
    assert [rows[k]["n"] for k in ("GT mesh", "GT + E_fit + E_g", "GT + E_colli", "GT + E_cont")] == [1, 1, 1, 1]


def _rows(contacts, volumes, depths, floors=None):
    rows = [{"contact": c, "volume_cm3": v, "depth_cm": d} for c, v, d in zip(contacts, volumes, depths)]
    return rows if floors is None else [{**r, "floor_cm": f} for r, f in zip(rows, floors)]


def _pdist_mean(x: torch.Tensor) -> float:
    return float(pdist(x.reshape(len(x), -1).double().numpy()).mean())


def test_load_placements_returns_exactly_n():
    """load_placements gives the first n accepted grasps, no more (the stubs hold 8 of the mug)."""
    for n in (1, 2, 3):
        assert len(load_placements(DATA_STUBS / "grasps", "mug", n, split="test")) == n


def test_summarise_takes_means_and_the_largest_floor_offset():
    """summarise: contact ratio, volume and depth are means over the bodies (a skewed set: mean != median != max);
    floor_max_cm is the largest |offset| of one run."""
    s = summarise(_rows([1, 1, 0, 0], [0.0, 0.0, 0.3, 9.7], [0.0, 0.1, 0.2, 1.7], [-0.5, 0.2, 4.0, -1.0]))
    assert s["contact_ratio"] == pytest.approx(0.5)
    assert s["volume_cm3"] == pytest.approx(10.0 / 4)
    assert s["depth_cm"] == pytest.approx(2.0 / 4)
    assert s["floor_abs_cm"] == pytest.approx(5.7 / 4) and s["floor_max_cm"] == pytest.approx(4.0)


def test_object_seed_index_is_the_default_list_position():
    """An object's draws are seeded by its place in the default test list, so a run on some objects draws what the
    full run draws (private helper: the public path would need all six objects' grasps)."""
    for i, name in enumerate(EvalConfig.objects):
        assert ES._object_index(name, 0) == i
    assert ES._object_index("pitcher", 5) == 5


def test_stage3_variants_have_the_terms_of_tab2():
    """SAGA Tab. 2 / S.3-S.4: 'E_fit + E_g' has no E_colli / E^o_cont, '+ E_colli' adds the collision term only,
    '+ E_cont' both; the heuristic optimisation is E_colli + the heuristic contact term; E_g everywhere."""
    V = ES.VARIANTS
    assert V["fit_g"] == dict(collision=False, contact=False, ground=True, heuristic=False)
    assert V["fit_g_colli"] == dict(collision=True, contact=False, ground=True, heuristic=False)
    assert V["full"] == dict(collision=True, contact=True, ground=True, heuristic=False)
    assert V["heuristic"] == dict(collision=True, contact=False, ground=True, heuristic=True)


def test_cli_objects_must_be_held_out_test_objects(tmp_path, capsys):
    """--objects takes only the test split's objects: a validation object ('apple') is refused before any work."""
    assert ES.main(["--data", str(tmp_path), "--out", str(tmp_path / "o.json"), "--objects", "apple"]) == 2
    err = capsys.readouterr().err
    assert "'apple' is not one of the held-out test objects" in err


def test_body_rows_measure_against_the_object_turned_by_the_placement_rotation(monkeypatch):
    """The mesh a body is measured against is the catalogue object turned by the placement's rotation: the
    placement's surface points (object frame) lie on it (mug placements are turned ~170-190 deg about z)."""
    import graspkit.metrics as M
    from graspkit.body import BodyModel

    seen = []
    real = M.grasp_metrics
    monkeypatch.setattr(M, "grasp_metrics", lambda v, f, mesh, **kw: seen.append(mesh.copy()) or real(v, f, mesh, **kw))
    bm = BodyModel.from_file(default_model_path())
    pls = load_placements(DATA_STUBS / "grasps", "mug", 2, split="test")
    with torch.no_grad():
        v = bm.forward_rotmats(torch.eye(3).expand(2, 55, 3, 3), betas=torch.zeros(2, 10),
                               transl=torch.tensor([[3.0, 0.0, 0.0]] * 2)).vertices
    ES.body_rows(bm, v, pls, 1, refine=1)
    assert len(seen) == 2
    for mesh, pl in zip(seen, pls):
        _, d, _ = trimesh.proximity.closest_point(mesh, pl.points.double().numpy())
        assert d.max() < 1e-3


@pytest.fixture(scope="module")
def spied_run(tmp_path_factory) -> dict[str, Any]:
    """One small evaluation (mug: 2 placements x 2 samples, 3 ground-truth grasps, 2 steps per stage) recording what
    each WholeGrasp sample was drawn for and which bodies / placements every body_rows call measured."""
    import graspkit.models.wholegrasp as W
    from graspkit.optim.grasppose import GraspPoseOpt

    ck = tmp_path_factory.mktemp("ck")
    shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", ck / "wholegrasp.pt")
    drawn, calls = [], []
    real_load, real_rows = W.load_wholegrasp, ES.body_rows

    def load(path=None, multitask=True):
        m = real_load(path, multitask)
        sample = m.sample
        m.sample = lambda pts, nrm, h, n, g, centre=None: drawn.extend([float(h)] * n) or sample(pts, nrm, h, n, g,
                                                                                                   centre=centre)
        return m

    def rows(bm, vertices, placements, per, refine=None):
        out = real_rows(bm, vertices, placements, per, refine)
        calls.append((vertices.detach().clone(), [p.height for p in placements for _ in range(per)], out))
        return out

    fits, real_fit = [], GraspPoseOpt.fit

    def fit(self, markers, obj, *a, **kw):
        r = real_fit(self, markers, obj, *a, **kw)
        terms = (self.cfg.collision, self.cfg.contact, self.cfg.heuristic)
        fits.append((terms, kw.get("stages"), kw.get("init"), r))
        return r

    cfg = EvalConfig(objects=("mug",), placements=2, samples=2, gt_grasps=3, steps=(2, 2, 2), polish=(0, 0.0),
                     refine=1)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(W, "load_wholegrasp", load)
        mp.setattr(ES, "body_rows", rows)
        mp.setattr(GraspPoseOpt, "fit", fit)
        res = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=ck)
    return {"res": res, "drawn": drawn, "calls": calls, "fits": fits}


def test_evaluate_takes_its_placements_and_ground_truth_counts(spied_run):
    """placements x samples bodies per model row, gt_grasps bodies per ground-truth row (here more GT grasps than
    placements)."""
    rows = spied_run["res"]["rows"]
    for k in ("WholeGrasp w/o opt.", "samples + E_colli", "WholeGrasp w/ opt. (Ours)"):
        assert rows[k]["n"] == 4
    for k in ("GT mesh", "GT + E_fit + E_g", "GT + E_colli", "GT + E_cont"):
        assert rows[k]["n"] == 3


def test_evaluate_measures_each_sample_against_the_placement_it_was_drawn_for(spied_run):
    """Every WholeGrasp sample's body is measured against the object placement (height) it was sampled for."""
    drawn = spied_run["drawn"]
    assert len(drawn) == 4 and len(set(drawn)) == 2
    for _, heights, _ in spied_run["calls"][:3]:                    # the three stage-3 variants' bodies
        assert heights[:4] == drawn


def test_evaluate_apd_is_of_the_final_bodies_markers(spied_run):
    """APD (SAGA after DLow) is taken on the 143 markers of the final, fitted bodies of each placement's samples."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_markers

    ids = torch.as_tensor(saga_markers(BodyModel.from_file(default_model_path())).vertex_ids)
    per = spied_run["res"]["per_object"]["mug"]
    for k, (v, _, _) in zip(("WholeGrasp w/o opt.", "samples + E_colli", "WholeGrasp w/ opt. (Ours)"),
                         spied_run["calls"][:3]):
        m = v[:4, ids]
        assert per[k]["apd"] == pytest.approx(np.mean([_pdist_mean(m[:2]), _pdist_mean(m[2:4])]), rel=1e-5)


def test_grabnet_row_apd_is_of_its_bodies_saga_markers(tmp_path, monkeypatch):
    """GrabNet-SMPLX's APD is the mean pairwise distance of SAGA's 143 marker vertices of the bodies it measured."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_markers
    from graspkit.models.wholegrasp import GRABNET_SMPLX_PATH, GrabNetSMPLX
    from graspkit.train import save_checkpoint

    shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / "wholegrasp.pt")
    torch.manual_seed(0)
    model = GrabNetSMPLX()
    torch.nn.init.normal_(model.dec[-1].weight, std=0.05)
    save_checkpoint(tmp_path / GRABNET_SMPLX_PATH.name, model.state())
    seen = []
    real = ES.body_rows
    monkeypatch.setattr(ES, "body_rows", lambda bm, v, *a, **k: seen.append(v.detach().clone()) or real(bm, v, *a, **k))
    cfg = EvalConfig(objects=("mug",), placements=1, samples=3, gt_grasps=1, steps=(2, 2, 2), polish=(0, 0.0),
                     refine=1)
    res = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path, grabnet_only=True)
    ids = torch.as_tensor(saga_markers(BodyModel.from_file(default_model_path())).vertex_ids)
    (v,) = seen
    assert res["rows"]["GrabNet-SMPLX"]["apd"] == pytest.approx(_pdist_mean(v[:, ids]), rel=1e-5)


def test_tab2_ground_truth_rows_are_fitted_with_their_rows_terms(spied_run):
    """Tab. 2: 'GT + E_fit + E_g', 'GT + E_colli' and 'GT + E_cont' are the ground-truth markers' bodies (the batch's
    last gt_grasps) of the stage-3 fits with exactly those terms (collision, E^o_cont)."""
    per = spied_run["res"]["per_object"]["mug"]
    for terms, key in (((False, False, False), "GT + E_fit + E_g"), ((True, False, False), "GT + E_colli"),
                       ((True, True, False), "GT + E_cont")):
        runs = [r.vertices.detach() for t, st, _, r in spied_run["fits"] if t == terms and st == (3,)]
        found = [out for v, _, out in spied_run["calls"] if any(v.shape == x.shape and torch.equal(v, x) for x in runs)]
        assert len(found) == 1, key                # (a stage 3 with restarts records its inner runs too)
        (rows,) = found
        want = summarise(rows[-3:])
        for m in ("contact_ratio", "volume_cm3", "depth_cm", "floor_abs_cm"):
            assert per[key][m] == pytest.approx(want[m], abs=1e-9), (key, m)


def test_single_row_holds_the_single_models_bodies(tmp_path, monkeypatch):
    """The WholeGrasp-single row is measured on the bodies fitted to WholeGrasp-single's samples: when its samples of a
    placement are all the same grasp, its APD is 0 while WholeGrasp's is not (stand-in: the single model's sample
    returns its first grasp n times)."""
    import graspkit.models.wholegrasp as W
    import graspkit.train as TR

    for name in ("wholegrasp.pt", "wholegrasp_single.pt"):
        shutil.copy(DATA_STUBS / "checkpoints" / "wholegrasp.pt", tmp_path / name)
    single_states, real_load, real_from = [], TR.load_checkpoint, W.WholeGraspVAE.from_state.__func__

    def load(path, *a, **kw):
        s = real_load(path, *a, **kw)
        if str(path).endswith("wholegrasp_single.pt"):
            single_states.append(s)
        return s

    def from_state(cls, state, *a, **kw):
        m = real_from(cls, state, *a, **kw)
        if any(state is s for s in single_states):
            sample = m.sample
            m.sample = lambda *a, **kw: (lambda g: type(g)(g.markers[:1].expand_as(g.markers).clone(), g.marker_contact,
                                                             g.object_contact, g.translation))(sample(*a, **kw))
        return m

    monkeypatch.setattr(TR, "load_checkpoint", load)
    monkeypatch.setattr(W.WholeGraspVAE, "from_state", classmethod(from_state))
    cfg = EvalConfig(objects=("mug",), placements=1, samples=2, gt_grasps=1, steps=(2, 2, 2), polish=(0, 0.0), refine=1)
    rows = evaluate(DATA_STUBS / "grasps", cfg, progress=False, out=None, checkpoints=tmp_path)["rows"]
    assert single_states and rows["WholeGrasp-single w/o opt."]["n"] == 2
    assert rows["WholeGrasp w/o opt."]["apd"] > 0.01
    assert rows["WholeGrasp-single w/o opt."]["apd"] < 1e-4


def test_lesson_examples_round_trip_through_float16(tmp_path):
    """save_examples writes the lesson's grasps (float16, weights-only) and load_examples reads back the same
    placements as load_placements gives, to float16's rounding; a split with no grasps is named."""
    out = ES.save_examples(DATA_STUBS / "grasps", tmp_path / "ex.pt", per_object=3, split="test")
    back = ES.load_examples(out)
    want = load_placements(DATA_STUBS / "grasps", "mug", 3, split="test")
    assert [p.name for p in back] == ["mug"] * 3
    for a, b in zip(back, want):
        torch.testing.assert_close(a.markers, b.markers, atol=2e-3, rtol=1e-3)
        torch.testing.assert_close(a.points, b.points, atol=2e-3, rtol=1e-3)
        torch.testing.assert_close(a.rotation, b.rotation)                     # kept in full precision
        assert a.height == pytest.approx(b.height, abs=1e-3)
        assert torch.equal(a.marker_contact, b.marker_contact.half().float())
    with pytest.raises(ValueError, match="root: no val grasps in"):
        ES.save_examples(DATA_STUBS / "grasps", tmp_path / "none.pt", split="val")
    assert not (tmp_path / "none.pt").exists()
