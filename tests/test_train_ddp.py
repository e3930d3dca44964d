"""The shared training loop under torchrun with DDP (gloo, two CPU processes): ranks keep identical weights."""
import os
import subprocess
import sys
import textwrap

import torch

WORKER = textwrap.dedent('''
    import os, sys, torch
    from torch.utils.data import TensorDataset
    from graspkit.train import TrainConfig, fit, init_distributed

    assert init_distributed()
    rank = torch.distributed.get_rank()
    g = torch.Generator().manual_seed(0)
    x = torch.randn(64, 4, generator=g)
    y = x @ torch.tensor([[1.0], [-2.0], [0.5], [3.0]])
    torch.manual_seed(rank)                       # different initial weights: DDP must broadcast rank 0's
    model = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1))
    step = lambda m, b, e: {"loss": (m(b[0]) - b[1]).pow(2).mean()}
    hist = fit(model, step, TensorDataset(x, y), TrainConfig(epochs=3, batch_size=8, lr=1e-2, num_threads=1),
               checkpoint=sys.argv[1] + "/ck.pt", progress=False)
    torch.save({k: v for k, v in model.state_dict().items()}, sys.argv[1] + f"/rank{rank}.pt")
    torch.distributed.barrier()                   # both ranks' weights are on disk
    # leave without gloo's teardown: under a loaded machine one CI run saw rank 1 abort in it ("terminate called
    # without an active exception", SIGABRT) after both ranks had written their weights; the OS closes the sockets
    os._exit(0)
''')


def test_two_ranks_train_to_identical_weights(tmp_path):
    script = tmp_path / "worker.py"
    script.write_text(WORKER)
    r = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
                        str(script), str(tmp_path)], capture_output=True, text=True, timeout=240,
                       env={**os.environ, "TMPDIR": str(tmp_path)})    # torchelastic's error-file folder goes here
    assert r.returncode == 0, r.stderr[-3000:]
    a = torch.load(tmp_path / "rank0.pt", weights_only=True)
    b = torch.load(tmp_path / "rank1.pt", weights_only=True)
    assert (tmp_path / "ck.pt").is_file()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    torch.manual_seed(0)
    fresh = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1))
    assert not torch.equal(fresh[0].weight, a["0.weight"])      # it trained


def test_a_step_that_bypasses_forward_is_refused_under_a_process_group(tmp_path):
    """fit(ddp=False) (WholeGrasp, the pose prior, MotionFill, WANDR: steps that call loss / encode / decode) refuses
    an initialised process group instead of training ranks out of step; ddp=True trains."""
    import pytest
    from torch.utils.data import TensorDataset

    from graspkit.train import TrainConfig, fit

    torch.distributed.init_process_group("gloo", init_method=f"file://{tmp_path / 'store'}", rank=0, world_size=1)
    try:
        model = torch.nn.Linear(2, 1)
        data = TensorDataset(torch.randn(8, 2), torch.randn(8, 1))
        step = lambda m, b, e: {"loss": (m(b[0]) - b[1]).pow(2).mean()}      # noqa: E731
        cfg = TrainConfig(epochs=1, batch_size=4, num_threads=1)
        with pytest.raises(RuntimeError, match="Linear's training step calls methods other than forward"):
            fit(model, step, data, cfg, progress=False, ddp=False)
        assert len(fit(model, step, data, cfg, progress=False)) == 1
    finally:
        torch.distributed.destroy_process_group()
