"""The shared training loop (resume = uninterrupted, atomic weights-only checkpoints) and the VAE blocks."""
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import TensorDataset

from graspkit.models.blocks import ResBlock, kl_standard_normal, mlp, reparameterize, robust_kl
from graspkit.train import TrainConfig, fit, load_checkpoint, save_checkpoint


def _problem():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(96, 4, generator=g)
    y = x @ torch.tensor([[1.0], [-2.0], [0.5], [3.0]]) + 0.1
    return TensorDataset(x, y)


def _step(model, batch, epoch):
    x, y = batch
    return {"loss": (model(x) - y).pow(2).mean()}


def test_fit_learns_a_linear_map():
    torch.manual_seed(0)
    model = torch.nn.Linear(4, 1)
    hist = fit(model, _step, _problem(), TrainConfig(epochs=60, batch_size=16, lr=5e-2, grad_clip=None), progress=False,
               val_dataset=_problem())
    assert hist[-1]["loss"] < 1e-3 < hist[0]["loss"] and hist[-1]["val_loss"] < 1e-3


def test_resume_gives_the_same_weights_as_an_uninterrupted_run(tmp_path):
    cfg = TrainConfig(epochs=6, batch_size=16, lr=1e-2, seed=3)
    torch.manual_seed(1)
    a = torch.nn.Linear(4, 1)
    b = torch.nn.Linear(4, 1)
    b.load_state_dict(a.state_dict())
    fit(a, _step, _problem(), cfg, progress=False)
    ck = tmp_path / "b.pt"
    fit(b, _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=3)   # interrupted
    state = load_checkpoint(ck)
    assert (tmp_path / "b.csv").read_text().count("\n") == 4      # header + 3 epochs
    assert state["epoch"] == 3 and not list(tmp_path.glob("*.tmp"))
    b2 = torch.nn.Linear(4, 1)
    fit(b2, _step, _problem(), cfg, checkpoint=ck, progress=False)  # resumes at epoch 3
    assert load_checkpoint(ck)["epoch"] == 6
    for p, q in zip(a.parameters(), b2.parameters()):
        torch.testing.assert_close(p, q)


def test_a_resumed_run_writes_the_bytes_of_a_run_in_one_go(tmp_path):
    """A run stopped and resumed ended with every tensor and history value of a run in one go, but other bytes (an
    independent check: the history's unpickled keys were other objects than the code's, so pickle wrote them again),
    and `file_key`, which names a run started from the file, differed. Equal values now give equal bytes."""
    from graspkit.train import file_key

    cfg = TrainConfig(epochs=4, batch_size=16, lr=1e-2, seed=2)
    runs = []
    for stops in ((), (1, 3)):
        torch.manual_seed(1)
        model, ck = torch.nn.Linear(4, 1), tmp_path / f"run{len(stops)}" / "r.pt"
        for stop in stops:
            fit(model, _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=stop, val_dataset=_problem())
            model = torch.nn.Linear(4, 1)                                   # a new process: a fresh model, resumed
        fit(model, _step, _problem(), cfg, checkpoint=ck, progress=False, val_dataset=_problem())
        runs.append(ck)
    a, b = load_checkpoint(runs[0]), load_checkpoint(runs[1])
    assert a["history"] == b["history"] and len(a["history"]) == 4 and "val_loss" in a["history"][0]
    assert runs[0].read_bytes() == runs[1].read_bytes() and file_key(runs[0]) == file_key(runs[1])


def _noisy_step(model, batch, epoch):
    """A step that draws from torch's global RNG, as every VAE step does (reparameterisation, dropout)."""
    x, y = batch
    return {"loss": (model(x + 0.1 * torch.randn_like(x)) - y).pow(2).mean()}


def test_resume_of_a_step_that_draws_random_numbers_gives_the_same_weights(tmp_path):
    """The random state goes into the checkpoint: an interrupted run of a noisy step, resumed, ends with the weights of
    the uninterrupted run, bit for bit."""
    cfg = TrainConfig(epochs=4, batch_size=16, lr=1e-2, seed=3)
    torch.manual_seed(1)
    a, b = torch.nn.Linear(4, 1), torch.nn.Linear(4, 1)
    b.load_state_dict(a.state_dict())
    fit(a, _noisy_step, _problem(), cfg, progress=False)
    ck = tmp_path / "b.pt"
    fit(b, _noisy_step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=2)
    torch.manual_seed(12345)                                    # whatever the process did in between
    b2 = torch.nn.Linear(4, 1)
    fit(b2, _noisy_step, _problem(), cfg, checkpoint=ck, progress=False)
    for p, q in zip(a.parameters(), b2.parameters()):
        assert torch.equal(p, q)


def test_each_epoch_sees_every_sample_once_in_its_own_order():
    """The data order of epoch e comes from seed + e: each epoch a permutation of the samples, not one order
    repeated."""
    class Indices(torch.utils.data.Dataset):
        def __len__(self):
            return 10

        def __getitem__(self, i):
            return torch.tensor([float(i)])

    seen = []

    def record(model, batch, epoch):
        seen.append(batch[:, 0].long().tolist())
        return {"loss": model(batch).sum() * 0}

    fit(torch.nn.Linear(1, 1), record, Indices(), TrainConfig(epochs=3, batch_size=10, seed=0), progress=False)
    assert len(seen) == 3 and all(sorted(o) == list(range(10)) for o in seen)
    assert len({tuple(o) for o in seen}) == 3


def test_a_batchnorm_model_skips_a_last_batch_of_one_and_other_models_keep_it():
    """9 samples in batches of 4: a BatchNorm layer cannot train on the last batch of one (torch raises "Expected
    more than 1 value per channel", an independent check on WholeGrasp-VAE); it is skipped, a different sample each
    epoch, while a model without BatchNorm still sees all 9. One sample alone is refused for a BatchNorm model."""
    class Indices(torch.utils.data.Dataset):
        def __init__(self, n):
            self.n = n

        def __len__(self):
            return self.n

        def __getitem__(self, i):
            return torch.tensor([float(i)])

    def recorder(seen):
        def step(model, batch, epoch):
            seen.append((epoch, batch[:, 0].long().tolist()))
            return {"loss": model(batch).pow(2).mean()}
        return step

    cfg = TrainConfig(epochs=3, batch_size=4, seed=0)
    seen_bn: list = []
    bn = torch.nn.Sequential(torch.nn.Linear(1, 3), torch.nn.BatchNorm1d(3), torch.nn.Linear(3, 1))
    fit(bn, recorder(seen_bn), Indices(9), cfg, progress=False)
    per_epoch = [[i for e, b in seen_bn if e == k for i in b] for k in range(3)]
    assert all(len(o) == 8 and len(set(o)) == 8 for o in per_epoch)
    assert len({tuple(set(range(9)) - set(o)) for o in per_epoch}) > 1      # not always the same sample left out
    assert all(len(b) > 1 for _, b in seen_bn)
    seen_lin: list = []
    fit(torch.nn.Linear(1, 1), recorder(seen_lin), Indices(9), cfg, progress=False)
    assert sorted(len(b) for e, b in seen_lin if e == 0) == [1, 4, 4]
    with pytest.raises(ValueError, match="dataset: .*BatchNorm.* at least 2"):
        fit(bn, recorder([]), Indices(1), cfg, progress=False)
    with pytest.raises(ValueError, match="batch_size: .*BatchNorm.* at least 2, got 1"):   # every batch one sample
        fit(bn, recorder([]), Indices(9), TrainConfig(epochs=1, batch_size=1), progress=False)


def test_logged_terms_are_per_sample_means_with_a_short_last_batch():
    """70 samples in batches of 64 + 6: the mean of batch means weighted the 6 as much as the 64 (+32 % on the
    pose prior's validation loss, an independent check)."""
    from graspkit.train import evaluate

    x = torch.arange(70, dtype=torch.float32)[:, None]
    data = TensorDataset(x, x)
    cfg = TrainConfig(epochs=1, batch_size=64, lr=1e-3)
    value = lambda m, b, e: {"loss": b[0].mean()}                  # noqa: E731  a batch's mean of 0..69
    assert evaluate(torch.nn.Linear(1, 1), value, data, cfg)["loss"] == pytest.approx(34.5)   # not (31.5 + 66.5) / 2
    seen, net = [], torch.nn.Linear(1, 1).train()
    evaluate(net, lambda m, b, e: seen.append(m.training) or {"loss": b[0].mean()}, data, cfg)
    assert seen == [False, False] and net.training              # in eval mode inside, the caller's mode after
    model = torch.nn.Linear(1, 1)
    hist = fit(model, lambda m, b, e: {"loss": m(b[0]).mean() * 0 + b[0].mean()}, data, cfg, progress=False)
    assert hist[0]["loss"] == pytest.approx(34.5)


def test_a_state_already_at_stop_at_returns_its_history_and_a_lost_csv_row_is_rewritten(tmp_path):
    """A run killed after saving an epoch but before its CSV (or, for WANDR's --select-val, before scoring it):
    the same command once trained to the end (past stop_at) and never rewrote the missing row."""
    from graspkit.train import write_history_csv

    cfg = TrainConfig(epochs=4, batch_size=16, lr=1e-2, seed=3)
    ck = tmp_path / "run.pt"
    torch.manual_seed(1)
    model = torch.nn.Linear(4, 1)
    fit(model, _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=2)
    weights = {k: v.clone() for k, v in model.state_dict().items()}
    again = fit(model, _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=2)
    assert len(again) == 2 and load_checkpoint(ck)["epoch"] == 2
    assert all(torch.equal(weights[k], v) for k, v in model.state_dict().items())
    hist = fit(model, _step, _problem(), cfg, checkpoint=ck, progress=False)
    write_history_csv(ck.with_suffix(".csv"), hist[:-1])           # the kill's state: 4 epochs saved, 3 rows
    fit(model, _step, _problem(), cfg, checkpoint=ck, progress=False)
    assert ck.with_suffix(".csv").read_text().count("\n") == 1 + 4


def test_load_checkpoint_names_a_missing_or_pickled_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.pt"):
        load_checkpoint(tmp_path / "nope.pt")
    bad = tmp_path / "bad.pt"
    torch.save({"obj": object()}, bad)
    with pytest.raises(ValueError, match="bad.pt: holds more than tensors.*cannot be read without pickle") as err:
        load_checkpoint(bad)
    assert "weights_only` set to `False`" not in str(err.value)      # torch's advice to unpickle is not passed on
    text = tmp_path / "notes.pt"
    text.write_text("x")
    with pytest.raises(ValueError, match="notes.pt: not a torch checkpoint"):
        load_checkpoint(text)
    arrays = tmp_path / "arrays.npz"                                 # a zip as well, but NumPy's
    np.savez(arrays, w=np.zeros(3))
    with pytest.raises(ValueError, match="arrays.npz: not a torch checkpoint.*NumPy .npz archive"):
        load_checkpoint(arrays)


def test_save_checkpoint_keeps_the_old_file_on_failure_and_concurrent_writers_apart(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    ck = tmp_path / "c.pt"
    save_checkpoint(ck, {"w": torch.ones(3)})
    with pytest.raises(Exception):
        save_checkpoint(ck, {"w": torch.zeros(3), "bad": lambda: 0})     # unpicklable: fails half-way
    torch.testing.assert_close(load_checkpoint(ck)["w"], torch.ones(3))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.pt"]
    with ThreadPoolExecutor(4) as ex:                                    # writers of one path share no temporary file
        list(ex.map(lambda k: save_checkpoint(ck, {"w": torch.full((50_000,), float(k))}), range(8)))
    w = load_checkpoint(ck)["w"]
    assert float(w[0]) in range(8) and bool((w == w[0]).all())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.pt"]


def test_the_same_state_saved_twice_gives_the_same_bytes(tmp_path):
    """file_key hashes a checkpoint's bytes (a run started from it is named by them): two files of the same state,
    under different names, are the same bytes."""
    from graspkit.train import file_key

    state = {"model": {"w": torch.arange(6.0)}, "epoch": 3}
    a, b = save_checkpoint(tmp_path / "a.pt", state), save_checkpoint(tmp_path / "sub" / "b.pt", state)
    assert a.read_bytes() == b.read_bytes() and file_key(a) == file_key(b)
    # equal values made as other objects (keys built at run time, as unpickled ones are), in plain and ordered dicts
    from collections import OrderedDict

    def built(word: str) -> str:
        return "".join(list(word))

    def rows(key) -> list:
        return [OrderedDict([(key("loss"), 0.5), (key("epoch"), 1)]), {key("loss"): 0.25, key("epoch"): 2}]

    c = save_checkpoint(tmp_path / "c.pt", {"history": rows(str)})
    d = save_checkpoint(tmp_path / "d.pt", {"history": rows(built)})
    assert c.read_bytes() == d.read_bytes()
    net = torch.nn.Sequential(torch.nn.Linear(2, 2), torch.nn.LayerNorm(2))     # a state dict keeps its _metadata
    back = load_checkpoint(save_checkpoint(tmp_path / "m.pt", {"model": net.state_dict()}))["model"]
    assert back._metadata == net.state_dict()._metadata and list(back) == list(net.state_dict())
    net.load_state_dict(back)


def test_kl_matches_torch_distributions_and_robust_kl_is_psi_of_it():
    g = torch.Generator().manual_seed(0)
    mu, logvar = torch.randn(5, 16, generator=g), torch.randn(5, 16, generator=g)
    q = torch.distributions.Normal(mu, torch.exp(0.5 * logvar))
    p = torch.distributions.Normal(torch.zeros_like(mu), torch.ones_like(mu))
    ref = torch.distributions.kl_divergence(q, p).sum(-1).mean()
    torch.testing.assert_close(kl_standard_normal(mu, logvar), ref)
    torch.testing.assert_close(robust_kl(mu, logvar), torch.sqrt(ref**2 + 1) - 1)
    assert float(robust_kl(torch.zeros(2, 3), torch.zeros(2, 3))) == 0.0


def test_reparameterize_is_seeded_and_has_the_right_moments():
    mu, logvar = torch.full((20000, 2), 1.5), torch.full((20000, 2), math.log(4.0))
    z1 = reparameterize(mu, logvar, torch.Generator().manual_seed(7))
    z2 = reparameterize(mu, logvar, torch.Generator().manual_seed(7))
    assert torch.equal(z1, z2)
    assert abs(float(z1.mean()) - 1.5) < 0.05 and abs(float(z1.std()) - 2.0) < 0.05


def test_blocks_shapes():
    assert ResBlock(8, 16)(torch.randn(4, 8)).shape == (4, 16)
    assert ResBlock(8, 8, norm="layer")(torch.randn(4, 8)).shape == (4, 8)
    net = mlp([3, 32, 32, 2])
    assert net(torch.randn(5, 3)).shape == (5, 2) and sum(isinstance(m, torch.nn.LayerNorm) for m in net) == 2


def test_file_key_follows_a_files_content(tmp_path):
    from graspkit.train import file_key

    f = tmp_path / "w.pt"
    f.write_bytes(b"one")
    k1 = file_key(f)
    assert file_key(f) == k1
    f.write_bytes(b"two")
    assert file_key(f) != k1 and file_key(tmp_path / "missing.pt") == "none" and file_key(None) == "none"


@pytest.mark.parametrize("kwargs, message", [({"epochs": 0}, "epochs: expected an integer >= 1"),
                                             ({"batch_size": -2}, "batch_size"), ({"seed": -1}, "seed"),
                                             ({"lr": -1e-3}, "lr: expected a finite number in \\[0, inf\\]"),
                                             ({"lr": "0.1"}, "lr"), ({"lr_min_ratio": -5}, "lr_min_ratio"),
                                             ({"weight_decay": -1}, "weight_decay"), ({"grad_clip": -1}, "grad_clip"), ({"lr": float("nan")}, "lr"), ({"num_threads": 0}, "num_threads"),
                                             ({"epochs": 2.5}, "epochs")])
def test_a_bad_training_setting_is_refused_before_any_work(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**kwargs)


def test_a_file_that_holds_no_checkpoint_dict_is_named(tmp_path):
    path = tmp_path / "bare.pt"
    torch.save(torch.zeros(3), path)
    with pytest.raises(ValueError, match="bare.pt: expected a graspkit checkpoint"):
        load_checkpoint(path)


def test_resuming_refuses_another_network_other_settings_or_a_damaged_file(tmp_path):
    cfg = TrainConfig(epochs=4, batch_size=16, lr=1e-2, seed=3)
    ck = tmp_path / "run.pt"
    fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=2)
    with pytest.raises(ValueError, match="run.pt: holds another network than Sequential"):
        fit(torch.nn.Sequential(torch.nn.Linear(4, 3), torch.nn.Linear(3, 1)), _step, _problem(), cfg,
            checkpoint=ck, progress=False)
    with pytest.raises(ValueError, match="run.pt: a run with other settings \\(lr 0.01 there, 0.5 here"):
        fit(torch.nn.Linear(4, 1), _step, _problem(), TrainConfig(epochs=4, batch_size=16, lr=0.5, seed=3),
            checkpoint=ck, progress=False)
    weights = tmp_path / "weights.pt"
    save_checkpoint(weights, {"model": torch.nn.Linear(4, 1).state_dict()})
    with pytest.raises(ValueError, match="weights.pt: not a training state"):
        fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, checkpoint=weights, progress=False)
    data = bytearray(ck.read_bytes())                       # bytes changed in place: torch.load alone accepts it
    with zipfile.ZipFile(ck) as zf:                         # inside the weights' entry (its local header: 30 bytes,
        e = next(i for i in zf.infolist() if i.filename.endswith("data/0"))   # the name and the extra field)
    at = e.header_offset + 30 + len(e.filename.encode()) + int.from_bytes(data[e.header_offset + 28:
                                                                               e.header_offset + 30], "little")
    data[at:at + 4] = b"\xff" * 4
    ck.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="run.pt: damaged"):
        load_checkpoint(ck)
    with pytest.raises(ValueError, match="time_limit_s"):
        fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, progress=False, time_limit_s=-5)


def test_a_run_writes_its_loss_curve_and_clears_a_killed_runs_temporary_files(tmp_path):
    import os
    import time

    from graspkit.paths import STALE_TMP_S

    ck = tmp_path / "run.pt"
    stale, fresh = tmp_path / ".run.pt.abc01234.tmp", tmp_path / ".run.pt.def01234.tmp"
    for f, age in ((stale, STALE_TMP_S + 60), (fresh, 1)):
        f.write_bytes(b"half")
        os.utime(f, (time.time() - age, time.time() - age))
    hist = fit(torch.nn.Linear(4, 1), _step, _problem(), TrainConfig(epochs=2, batch_size=16), checkpoint=ck,
               progress=False)
    png = (tmp_path / "run.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(hist) == 2
    assert not stale.exists() and fresh.exists()           # a writer at work now is left alone


def test_every_atomic_writer_syncs_the_file_before_renaming_it(tmp_path, monkeypatch):
    import os

    import numpy as np

    from graspkit.body.procedural import save_model_npz
    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import write_atomic

    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("rename", str(src), str(dst)))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    writers = {"a.pt": lambda p: save_checkpoint(p, {"w": torch.ones(2)}), "b.txt": lambda p: write_atomic(p, "x"),
               "c.npz": lambda p: write_npz_atomic(p, {"x": np.ones(2)}),
               "d.npz": lambda p: save_model_npz({"x": np.ones(2)}, p)}
    for name, write in writers.items():
        events.clear()
        write(tmp_path / name)
        renames = [e for e in events if e[0] == "rename"]
        assert len(renames) == 1 and renames[0][2] == str(tmp_path / name), (name, events)
        k = events.index(renames[0])
        assert ("fsync", renames[0][1]) in events[:k], (name, events)       # the data, before the rename
        assert ("fsync", str(tmp_path)) in events[k:], (name, events)       # the folder's entry, after it


def test_files_key_changes_when_data_are_remade_in_place_at_the_same_size(tmp_path):
    """GNet's and MNet's runs were keyed on the folder and the sample count: poses edited in place (same names, same
    sizes) resumed the old run and returned its weights bit for bit."""
    import numpy as np

    from graspkit.train import files_key

    for i in range(3):
        np.savez(tmp_path / f"grasp_{i:06d}.npz", pose=np.full(8, float(i)))
    (tmp_path / "notes.txt").write_text("not data")
    before = files_key(tmp_path)
    size = (tmp_path / "grasp_000001.npz").stat().st_size
    np.savez(tmp_path / "grasp_000001.npz", pose=np.full(8, 0.1))              # remade in place
    assert (tmp_path / "grasp_000001.npz").stat().st_size == size and files_key(tmp_path) != before
    (tmp_path / "notes.txt").write_text("other notes")                          # not matched by the pattern
    assert files_key(tmp_path) == files_key([tmp_path]) == files_key(tmp_path, "grasp_*.npz")


def _steep_problem():
    """32 samples of a steep linear map: large errors, large gradients."""
    g = torch.Generator().manual_seed(0)
    x = torch.randn(32, 4, generator=g)
    return TensorDataset(x, 100.0 * x.sum(1, keepdim=True) + 50.0)       # large errors: large gradients


def test_the_optimiser_sees_gradients_clipped_to_grad_clip():
    """The gradient that reaches the optimiser is clipped to cfg.grad_clip (read by an optimiser pre-step hook)."""
    norms = []

    def hook(opt, args, kwargs):
        g = [p.grad for group in opt.param_groups for p in group["params"] if p.grad is not None]
        norms.append(float(torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(x) for x in g]))))

    from torch.optim.optimizer import register_optimizer_step_pre_hook
    h = register_optimizer_step_pre_hook(hook)
    try:
        torch.manual_seed(0)
        fit(torch.nn.Linear(4, 1), _step, _steep_problem(), TrainConfig(epochs=2, batch_size=8, lr=1e-3, grad_clip=0.5),
            progress=False)
    finally:
        h.remove()
    assert len(norms) == 8
    assert max(norms) <= 0.5 * (1 + 1e-5) and min(norms) > 0.49    # every raw gradient was far above 0.5


def test_history_epochs_are_the_epochs_done(tmp_path):
    """The history's epochs are the epochs done (1, 2, ..), as the checkpoint counts them."""
    torch.manual_seed(0)
    ck = tmp_path / "run.pt"
    hist = fit(torch.nn.Linear(4, 1), _step, _steep_problem(), TrainConfig(epochs=3, batch_size=8), checkpoint=ck,
               progress=False)
    assert [h["epoch"] for h in hist] == [1, 2, 3]
    assert load_checkpoint(ck)["epoch"] == hist[-1]["epoch"] == 3


def _data():
    g = torch.Generator().manual_seed(0)
    return TensorDataset(torch.randn(12, 2, generator=g), torch.arange(12.0)[:, None])


def test_the_data_order_depends_only_on_the_seed_and_epoch_not_on_the_steps_random_draws():
    """_loader's contract ("order depends only on (seed, epoch)"): a step that draws random numbers and one that does
    not see the samples in the same order, epoch after epoch."""
    def run(draw):
        seen = []

        def step(model, batch, epoch):
            x, i = batch
            seen.append(i[:, 0].long().tolist())
            noise = torch.randn(50) if draw else torch.zeros(50)
            return {"loss": model(x).sum() * 0 + noise.sum() * 0}

        fit(torch.nn.Linear(2, 1), step, _data(), TrainConfig(epochs=3, batch_size=12, seed=5), progress=False)
        return seen

    quiet, noisy = run(False), run(True)
    assert len(quiet) == 3 and quiet == noisy


def test_the_seed_seeds_the_steps_random_draws():
    """TrainConfig.seed seeds the run: the first noise a step draws is that of torch.manual_seed(seed) whatever the
    process did before, so two seeds draw different noise and the same seed the same."""
    def first_noise(seed):
        drawn = []

        def step(model, batch, epoch):
            x, _ = batch
            drawn.append(torch.randn(8))
            return {"loss": model(x).sum() * 0}

        torch.manual_seed(1234)                       # whatever came before
        fit(torch.nn.Linear(2, 1), step, _data(), TrainConfig(epochs=1, batch_size=12, seed=seed), progress=False)
        return drawn[0]

    a, b, a2 = first_noise(1), first_noise(2), first_noise(1)
    assert torch.equal(a, a2)
    assert not torch.allclose(a, b)


@pytest.mark.parametrize("norm", ["batch", "layer"])
def test_resblock_applies_leaky_relu_after_adding_the_skip(norm):
    """ResBlock (GrabNet / SAGA's layout): y = LeakyReLU_0.2(n2(fc2(LeakyReLU_0.2(n1(fc1 x)))) + x). With fc1 = 0 and
    fc2 = a bias of -5 (so the residual branch gives -5 in every unit), x = 1 gives LeakyReLU(-4) = -0.8, where an
    activation before the sum would give LeakyReLU(-5) + 1 = 0."""
    torch.manual_seed(0)
    blk = ResBlock(4, 4, norm=norm).eval()
    with torch.no_grad():
        blk.fc1.weight.zero_(); blk.fc1.bias.zero_()
        blk.fc2.weight.zero_(); blk.fc2.bias.fill_(-5.0)
    if norm == "layer":                  # LayerNorm of a constant row is 0: give the branch its -5 through the bias
        with torch.no_grad():
            blk.n2.bias.fill_(-5.0)
    y = blk(torch.ones(3, 4))
    torch.testing.assert_close(y, torch.full((3, 4), -0.8), atol=1e-4, rtol=0)


def test_a_training_state_records_its_code_and_a_resume_by_other_code_warns(tmp_path, monkeypatch):
    """The state holds code_version(), a hash of the sources: equal for a copy of graspkit's tree, other once one
    byte of one file changes. Resuming with the same code is silent; with other code, or a state from before the code
    was recorded, it warns naming the file (the run key names settings, not code: MNet's held features of 2026-12-07
    needed a hand-made key entry so that an older run file was not resumed)."""
    import shutil
    import warnings

    import graspkit
    import graspkit.train as tr
    from graspkit.checks import GraspkitWarning

    same, other = tmp_path / "same", tmp_path / "other"          # two copies: a folder is hashed once per process
    for tree in (same, other):
        shutil.copytree(Path(graspkit.__file__).parent, tree, ignore=shutil.ignore_patterns("__pycache__"))
    with open(other / "models" / "mnet.py", "a") as f:
        f.write("#")
    assert tr.code_version(same) == tr.code_version() != tr.code_version(other)

    cfg = TrainConfig(epochs=3, batch_size=16, lr=1e-2, seed=0)
    ck = tmp_path / "r.pt"
    fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=1)
    assert load_checkpoint(ck)["code"] == tr.code_version()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, checkpoint=ck, progress=False, stop_at=2)
    monkeypatch.setattr(tr, "code_version", lambda root=None: "0123456789ab")
    with pytest.warns(GraspkitWarning, match=rf"checkpoint {ck}: a training state written by other graspkit sources") \
            as rec:
        fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, checkpoint=ck, progress=False)
    assert [w.filename for w in rec] == [__file__]          # the caller's line (a `graspkit train` note in the CLI)
    state = load_checkpoint(ck)
    assert state["epoch"] == 3 and state["code"] == "0123456789ab"
    save_checkpoint(ck, {k: v for k, v in state.items() if k != "code"} | {"epoch": 2})     # a state of before
    with pytest.warns(GraspkitWarning, match="did not record its sources"):
        fit(torch.nn.Linear(4, 1), _step, _problem(), cfg, checkpoint=ck, progress=False)
