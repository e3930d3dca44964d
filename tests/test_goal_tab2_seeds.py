"""tools/goal_tab2_seeds.py: GOAL Tab. 2 over training seeds (mean ± sd, MNet's paired differences)."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
ROWS = ("MNet", "MNet-w/o-IAA", "MNet-Pose", "1 output frame")


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("goal_tab2_seeds", ROOT / "tools" / "goal_tab2_seeds.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_summary_is_the_seeds_mean_sd_and_paired_differences(tool):
    """Mean and sample sd (numpy, ddof=1) per row and part; MNet − ablation per seed, the seeds where MNet is
    lower counted, and the paired t-test's two-sided p (the statistic by hand); two seeds give no p."""
    rng = np.random.default_rng(3)
    per_seed = {s: {r: {p: float(rng.uniform(10, 30)) for p in ("body", "hand", "feet")} for r in ROWS}
                for s in (0, 1, 2, 5)}
    got = tool.summarise(per_seed)
    for r in ROWS:
        for p in ("body", "hand", "feet"):
            v = np.array([per_seed[s][r][p] for s in per_seed])
            assert got["rows"][r][p]["mean"] == pytest.approx(v.mean())
            assert got["rows"][r][p]["sd"] == pytest.approx(v.std(ddof=1))
            if r != "MNet":
                d = np.array([per_seed[s]["MNet"][p] for s in per_seed]) - v
                assert got["mnet_minus"][r][p]["mean"] == pytest.approx(d.mean())
                assert got["mnet_minus"][r][p]["sd"] == pytest.approx(d.std(ddof=1))
                assert got["mnet_minus"][r][p]["below"] == int((d < 0).sum())
                t = d.mean() / (d.std(ddof=1) / np.sqrt(len(d)))        # the paired t statistic, by hand
                assert got["mnet_minus"][r][p]["p"] == pytest.approx(2 * stats.t.sf(abs(t), len(d) - 1))
    assert "MNet" not in got["mnet_minus"]
    two = tool.summarise({s: per_seed[s] for s in (0, 1)})
    assert two["mnet_minus"]["MNet-Pose"]["body"]["p"] is None and "below) |" in tool.table(two)
    line = next(x for x in tool.table(got).splitlines() if x.startswith("| MNet-Pose |"))
    assert f"{got['rows']['MNet-Pose']['hand']['mean']:.2f} ± {got['rows']['MNet-Pose']['hand']['sd']:.2f}" in line


def test_the_tool_trains_what_is_missing_and_writes_every_seed(tool, tmp_path, monkeypatch, capsys):
    """One job in-process: a checkpoint already in <out>/seed<S> is measured, not trained again (one of other epochs
    is refused); the JSON holds each
    seed's rows as tab2_results gave them (stand-ins: the error is seed + variant number, a numpy float as the
    evaluator's; the first real run failed writing one) and the summary."""
    import graspkit.eval_goal as eg
    from graspkit.train import save_checkpoint

    trained, measured = [], []

    def fake_train(folders, path, variant, epochs, time_limit, seed, threads, run_dir, progress):
        assert time_limit is None and threads == 1 and epochs == 3
        trained.append((seed, variant))
        info = {"variant": variant, "epochs": epochs, "seconds": 10.0 * seed + len(variant)}
        save_checkpoint(path, {"extra": info})
        return info

    def fake_tab2(folders, stubs, stride):
        measured.append(Path(stubs).name)
        files = {f: n for n, f in enumerate(eg.TAB2_ROWS)}
        seed = int(Path(stubs).name.removeprefix("seed"))
        rows = {eg.TAB2_ROWS[f]: {p: np.float64(seed + files[f]) for p in ("body", "hand", "feet")}
                for f in files if (Path(stubs) / f).is_file()}
        return {"tab2": rows, "tab2_windows": 7, "tab2_seconds": 0.1}

    monkeypatch.setattr(eg, "run_train_mnet", fake_train)
    monkeypatch.setattr(eg, "tab2_results", fake_tab2)
    (tmp_path / "out" / "seed1").mkdir(parents=True)
    save_checkpoint(tmp_path / "out" / "seed1" / "mnet_pose.pt", {"extra": {"variant": "pose", "epochs": 3,
                                                                           "seconds": 99.0}})
    out = tmp_path / "t2.json"
    assert tool.main(["--out", str(tmp_path / "out"), "--data", str(tmp_path), "--seeds", "0", "1", "--epochs", "3",
                      "--jobs", "1", "--json", str(out)]) == 0
    assert sorted(trained) == sorted({(s, v) for s in (0, 1) for v in tool.ORDER} - {(1, "pose")})
    r = json.loads(out.read_text())
    assert r["per_seed"]["1"]["MNet-Pose"]["body"] == 3 and r["per_seed"]["0"]["1 output frame"]["hand"] == 3
    assert r["rows"]["MNet-w/o-IAA"]["feet"]["mean"] == pytest.approx(1.5)
    assert r["mnet_minus"]["MNet-Pose"]["body"]["below"] == 2 and r["windows"] == 7
    assert r["train_seconds"]["seed1/pose"] == 99.0 and r["train_seconds"]["seed1/no_iaa"] == 16.0
    assert "| MNet |" in capsys.readouterr().out
    assert sorted(measured) == ["seed0", "seed1"]
    # run again: the measurements kept in <out>/seed<S>/tab2.json are read, nothing trained or measured
    assert tool.main(["--out", str(tmp_path / "out"), "--data", str(tmp_path), "--seeds", "0", "1", "--epochs", "3",
                      "--jobs", "1", "--json", str(out)]) == 0
    assert len(trained) == 7 and len(measured) == 2 and json.loads(out.read_text())["per_seed"] == r["per_seed"]
    # a checkpoint of another command (other epochs) is refused before any work, the JSON kept
    before = out.read_text()
    with pytest.raises(SystemExit) as e:
        tool.main(["--out", str(tmp_path / "out"), "--data", str(tmp_path), "--seeds", "0", "1", "--epochs", "4",
                   "--jobs", "1", "--json", str(out)])
    assert e.value.code == 2 and "trained with other epochs (3, expected 4)" in capsys.readouterr().err
    assert out.read_text() == before and len(trained) == 7
    # one of another seed or other data copied in is refused (seed and files recorded since 2026-12-07), and a file
    # that is not a checkpoint named
    for extra, said in (({"seed": 0}, "seed (0, expected 1)"), ({"seed": 1, "files": "x"}, "files ('x', expected")):
        save_checkpoint(tmp_path / "out" / "seed1" / "mnet_pose.pt",
                        {"extra": {"variant": "pose", "epochs": 3, "seconds": 9.0, **extra}})
        with pytest.raises(SystemExit):
            tool.main(["--out", str(tmp_path / "out"), "--data", str(tmp_path), "--seeds", "0", "1", "--epochs", "3",
                       "--jobs", "1"])
        assert said in capsys.readouterr().err
    (tmp_path / "out" / "seed1" / "mnet_pose.pt").write_text("not torch")
    with pytest.raises(SystemExit):
        tool.main(["--out", str(tmp_path / "out"), "--data", str(tmp_path), "--seeds", "1", "--epochs", "3"])
    assert "--out: checkpoint " in capsys.readouterr().err and len(trained) == 7


def test_the_tool_refuses_repeated_seeds(tool, tmp_path, capsys):
    """--seeds 0 0 would measure one training twice and call it a spread."""
    with pytest.raises(SystemExit) as e:
        tool.main(["--out", str(tmp_path), "--seeds", "0", "0"])
    assert e.value.code == 2 and "--seeds: expected distinct seeds" in capsys.readouterr().err


def _alive(pid: int) -> bool:
    """A process that runs (not gone, not a zombie waiting to be reaped)."""
    try:
        return " Z " not in Path(f"/proc/{pid}/stat").read_text().split(")", 1)[1][:4]
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_the_workers_stop_with_a_terminated_parent(tmp_path):
    """A SIGTERM to the tool while two spawned workers run (each napping 60 s here) ends the parent with 143 and
    terminates both workers: with concurrent.futures' pool they ran on, and two such trainings ran beside the next run
    for ten minutes."""
    import os
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "napper.py").write_text("import os, time\n\ndef nap(path):\n"
                                        "    open(path, 'w').write(str(os.getpid()))\n    time.sleep(60)\n")
    (tmp_path / "run.py").write_text("import sys\nimport goal_tab2_seeds as t\nimport napper\n"
                                     "if __name__ == '__main__':\n"
                                     "    t._map(napper.nap, [(sys.argv[1] + '/a',), (sys.argv[1] + '/b',)], 2)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "tools"), str(tmp_path), str(ROOT)])}
    proc = subprocess.Popen([sys.executable, str(tmp_path / "run.py"), str(tmp_path)], env=env,
                            start_new_session=True)
    try:
        t0 = time.monotonic()
        while not all((tmp_path / n).is_file() and (tmp_path / n).read_text() for n in "ab"):
            assert time.monotonic() - t0 < 60 and proc.poll() is None, "the workers did not start"
            time.sleep(0.1)
        pids = [int((tmp_path / n).read_text()) for n in "ab"]
        assert all(_alive(p) for p in pids)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 128 + signal.SIGTERM
    finally:                         # whatever failed, nothing of it left running (its own session: its group)
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    t0 = time.monotonic()
    while any(_alive(p) for p in pids) and time.monotonic() - t0 < 15:
        time.sleep(0.1)
    assert not any(_alive(p) for p in pids)
