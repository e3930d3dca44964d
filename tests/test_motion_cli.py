"""`graspkit data make`: files, resumability, determinism across workers, atomic writes."""
import subprocess
import sys

import numpy as np

from graspkit.data import load_motion
from graspkit.data.cli import clip_seed, make_dataset


def test_make_resume_and_determinism(tmp_path):
    a = make_dataset("reach", 2, 7, tmp_path / "a", workers=1, progress=False)
    assert [p.name for p in a] == ["reach_000000.npz", "reach_000001.npz"]
    stamp = [p.stat().st_mtime_ns for p in a]
    b = make_dataset("reach", 3, 7, tmp_path / "a", workers=1, progress=False)      # resumes: only clip 2 is new
    assert [p.stat().st_mtime_ns for p in b[:2]] == stamp and b[2].exists()
    m = load_motion(b[2])
    assert m.goal is not None and m.fps == 30.0
    assert not list((tmp_path / "a").glob("*.tmp")) and not list((tmp_path / "a").glob(".*"))
    assert clip_seed(7, "reach", 2) != clip_seed(7, "locomotion", 2) != clip_seed(8, "reach", 2)


def test_resume_makes_a_damaged_clip_again(tmp_path, capsys):
    """A clip cut short (a copy stopped half-way) or with a changed byte is made again on resume, to the same
    bytes; the intact clip is left alone."""
    a = make_dataset("reach", 2, 7, tmp_path, workers=1, progress=False)
    whole, stamp = a[0].read_bytes(), a[1].stat().st_mtime_ns
    for damage in (whole[: len(whole) // 2], whole[:100] + bytes([whole[100] ^ 0xFF]) + whole[101:]):
        a[0].write_bytes(damage)
        make_dataset("reach", 2, 7, tmp_path, workers=1, progress=False)
        assert a[0].read_bytes() == whole and a[1].stat().st_mtime_ns == stamp
        assert "1 damaged reach clips made again (reach_000000.npz)" in capsys.readouterr().err


def test_a_folder_takes_only_files_of_its_own_run(tmp_path):
    """Clips of another seed or body model are refused in a folder that holds a run's clips (a resumed or extended
    run must be the same run); the default body named by its path is the same run."""
    import json

    import pytest

    from graspkit.paths import default_model_path

    from graspkit.body import BodyModel

    make_dataset("reach", 1, 7, tmp_path, workers=1, progress=False)
    assert json.loads((tmp_path / "graspkit_make_reach.json").read_text()) == {
        "kind": "reach", "model": None, "seed": 7, "body": BodyModel.from_file(default_model_path()).digest()}
    with pytest.raises(ValueError, match=r"--out: .*\(seed: 7 there, 8 now\)"):
        make_dataset("reach", 2, 8, tmp_path, workers=1, progress=False)
    assert not (tmp_path / "reach_000001.npz").exists()
    make_dataset("reach", 2, 7, tmp_path, workers=1, progress=False, model=str(default_model_path()))
    assert (tmp_path / "reach_000001.npz").exists()
    with pytest.raises(ValueError, match="nope.npz: no such body-model file"):      # before any worker starts
        make_dataset("reach", 3, 7, tmp_path, workers=2, progress=False, model=str(tmp_path / "nope.npz"))
    record = tmp_path / "graspkit_make_reach.json"
    for damaged, message in (('{"kind": "re', "is damaged"), ("[1, 2]", "holds a list")):
        record.write_text(damaged)
        with pytest.raises(ValueError, match=rf"--out: .*graspkit_make_reach\.json {message}"):
            make_dataset("reach", 3, 7, tmp_path, workers=1, progress=False)
        assert not (tmp_path / "reach_000002.npz").exists()


def test_a_folder_refuses_another_body_behind_the_same_name(tmp_path, monkeypatch):
    """The record named the body by its path (None for the default), so GRASPKIT_MODEL pointing at a taller body, or
    the model file changed in place, added that body's clips to the folder (an independent check). The body's digest
    is in the record now: both are refused, and a record written before the digest was kept still extends."""
    import json

    import pytest

    from graspkit.paths import default_model_path

    with np.load(default_model_path(), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    tall = tmp_path / "tall.npz"
    np.savez_compressed(tall, **{**arrays, "v_template": arrays["v_template"] * 1.2})
    make_dataset("reach", 1, 7, tmp_path / "a", workers=1, progress=False)
    monkeypatch.setenv("GRASPKIT_MODEL", str(tall))
    with pytest.raises(ValueError, match=r"--out: .*\(body: '[0-9a-f]+' there, '[0-9a-f]+' now\)"):
        make_dataset("reach", 2, 7, tmp_path / "a", workers=1, progress=False)
    monkeypatch.delenv("GRASPKIT_MODEL")
    own = tmp_path / "own.npz"
    np.savez_compressed(own, **arrays)
    make_dataset("reach", 1, 7, tmp_path / "b", workers=1, progress=False, model=str(own))
    np.savez_compressed(own, **{**arrays, "v_template": arrays["v_template"] * 1.2})          # changed in place
    with pytest.raises(ValueError, match=r"--out: .*\(body: "):
        make_dataset("reach", 2, 7, tmp_path / "b", workers=1, progress=False, model=str(own))
    record = tmp_path / "a" / "graspkit_make_reach.json"
    record.write_text(json.dumps({"kind": "reach", "model": None, "seed": 7}))      # an older record
    make_dataset("reach", 2, 7, tmp_path / "a", workers=1, progress=False)
    assert (tmp_path / "a" / "reach_000001.npz").exists()


def test_cli_with_two_workers_writes_the_same_bytes(tmp_path):
    r = subprocess.run([sys.executable, "-m", "graspkit", "data", "make", "--kind", "locomotion", "--n", "2",
                        "--seed", "4", "--out", str(tmp_path / "p"), "--workers", "2"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "locomotion clips" in r.stderr                       # tqdm's progress bar
    one = make_dataset("locomotion", 2, 4, tmp_path / "s", workers=1, progress=False)
    for p in one:
        assert p.read_bytes() == (tmp_path / "p" / p.name).read_bytes()


def test_shipped_samples_are_what_the_cli_makes_with_seed_0():
    from pathlib import Path

    import numpy as np
    import torch

    from graspkit.body import BodyModel
    from graspkit.data import generate_locomotion, generate_reach
    from conftest import PROCEDURAL_MODEL

    stubs = Path(__file__).resolve().parents[1] / "data_stubs" / "motion"
    bm = BodyModel.from_file(PROCEDURAL_MODEL, dtype=torch.float32)
    for kind, gen in (("locomotion", generate_locomotion), ("reach", generate_reach)):
        files = sorted((stubs / kind).glob(f"{kind}_*.npz"))
        assert len(files) >= 5
        m, ref = load_motion(files[1]), gen(clip_seed(0, kind, 1), bm)
        # the procedural body may be refined after the samples were made: same plan, joints within a few mm
        assert m.num_frames == ref.num_frames and np.array_equal(m.betas, ref.betas.astype(np.float32))
        assert np.abs(m.joint_positions(bm) - ref.joint_positions(bm)).max() < 0.01
        assert (m.goal is not None) == (kind == "reach")


def _children(pid: int) -> list[int]:
    """Live processes whose parent is `pid` (Linux /proc)."""
    from pathlib import Path

    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def test_workers_exit_when_make_is_killed(tmp_path):
    """kill -9 of `data make` cannot close its process pool; its workers used to wait for work forever."""
    import os
    import signal
    import time

    import pytest

    if not os.path.isdir("/proc/self"):
        pytest.skip("needs Linux /proc")
    p = subprocess.Popen([sys.executable, "-m", "graspkit", "data", "make", "--kind", "locomotion", "--n", "40",
                          "--seed", "4", "--out", str(tmp_path / "k"), "--workers", "2"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: list[int] = []
    for _ in range(120):                                 # until the pool's two workers are up
        time.sleep(0.25)
        workers = _children(p.pid)
        if len(workers) >= 2 and list((tmp_path / "k").glob("*.npz")):
            break
    assert len(workers) >= 2
    os.kill(p.pid, signal.SIGKILL)
    p.wait()

    def running(w: int) -> bool:             # exited workers may stay as zombies where nothing reaps orphans
        try:
            return open(f"/proc/{w}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    for _ in range(40):
        time.sleep(0.25)
        if not any(running(w) for w in workers):
            break
    alive = [w for w in workers if running(w)]
    for w in alive:                                      # leave nothing behind if the check fails
        os.kill(w, signal.SIGKILL)
    assert not alive


def test_ctrl_c_stops_make_with_workers_at_once(tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) used to let the pool run every queued clip."""
    import os
    import signal
    import time

    def as_from_a_terminal() -> None:
        """In the child: SIGINT at its default, as a terminal's foreground job has it. A test run started in the
        background (`cmd &` in a script) inherits SIGINT ignored, and Python then keeps ignoring it."""
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    out = tmp_path / "c"
    p = subprocess.Popen([sys.executable, "-m", "graspkit", "data", "make", "--kind", "locomotion", "--n", "400",
                          "--seed", "4", "--out", str(out), "--workers", "2", "--quiet"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                         preexec_fn=as_from_a_terminal)
    for _ in range(240):                                 # until the pool has written a few clips
        time.sleep(0.25)
        if len(list(out.glob("*.npz"))) >= 2:
            break
    os.killpg(p.pid, signal.SIGINT)
    err = p.communicate(timeout=60)[1].decode()
    n = len(list(out.glob("*.npz")))
    assert p.returncode == 130 and "interrupted" in err, err
    assert 2 <= n < 100, n                               # the queued clips were cancelled, not run
    for f in out.glob("*.npz"):                          # and what is there loads
        load_motion(f)


def test_reach_chain_clips_are_the_generators_and_leave_the_other_kinds_seeds_alone(tmp_path, bm):
    import numpy as np

    from graspkit.data import generate_reach_chain
    from graspkit.data.cli import KINDS

    assert KINDS[:4] == ("locomotion", "reach", "reach_far", "reach_chain")   # clip seeds hash the kind's index: the
                                                                              # old sets stay
    files = make_dataset("reach_chain", 2, 3, tmp_path, workers=1, progress=False)
    assert [p.name for p in files] == ["reach_chain_000000.npz", "reach_chain_000001.npz"]
    for i, p in enumerate(files):
        m, want = load_motion(p), generate_reach_chain(clip_seed(3, "reach_chain", i), bm)
        assert np.allclose(m.poses, want.poses, atol=1e-6) and m.goal_frame == want.goal_frame


def test_reach_near_clips_are_the_generators(tmp_path, bm):
    import numpy as np

    from graspkit.data import generate_reach

    files = make_dataset("reach_near", 2, 3, tmp_path, workers=1, progress=False)
    assert [p.name for p in files] == ["reach_near_000000.npz", "reach_near_000001.npz"]
    for i, p in enumerate(files):
        m, want = load_motion(p), generate_reach(clip_seed(3, "reach_near", i), bm, near=True)
        assert np.allclose(m.poses, want.poses, atol=1e-6) and m.goal_frame == want.goal_frame


def _claim(out, seed, barrier, results):
    """A process that claims `out` for `seed` as `data make` does, released together with another."""
    from graspkit.data.cli import claim_folder

    barrier.wait()
    try:
        claim_folder(out, "locomotion", {"seed": seed, "model": None})
        results[seed] = "ok"
    except ValueError:
        results[seed] = "refused"


def test_two_runs_started_together_into_one_folder_do_not_both_claim_it(tmp_path):
    """Both saw no record and both wrote one (9 trials in 10, an independent check): the folder then held one seed's
    record and the other's files. The record is created exclusively now: exactly one of the two is refused, and the
    record names the seed that was accepted. A folder of older files without a record is taken with a warning and
    checked from then on (its record counts the files it did not check); a reach_far file is not an older reach file
    (reach_* matched it, a review)."""
    import json
    import multiprocessing as mp
    import warnings

    import pytest

    from graspkit.data.cli import claim_folder

    ctx = mp.get_context("fork")
    for trial in range(3):
        out = tmp_path / f"t{trial}"
        out.mkdir()
        with ctx.Manager() as manager:
            results, barrier = manager.dict(), manager.Barrier(2)
            procs = [ctx.Process(target=_claim, args=(out, seed, barrier, results)) for seed in (0, 1)]
            for p in procs:
                p.start()
            for p in procs:
                p.join(60)
            got = dict(results)
        assert sorted(got.values()) == ["ok", "refused"], got
        [winner] = [s for s, r in got.items() if r == "ok"]
        assert json.loads((out / "graspkit_make_locomotion.json").read_text())["seed"] == winner
        assert [p.name for p in out.iterdir()] == ["graspkit_make_locomotion.json"]       # no temporary left
    old = tmp_path / "old"
    old.mkdir()
    (old / "locomotion_000000.npz").write_bytes(b"")
    with pytest.warns(UserWarning, match="no record of the run that made them"):
        claim_folder(old, "locomotion", {"seed": 3, "model": None})
    assert json.loads((old / "graspkit_make_locomotion.json").read_text())["preexisting"] == 1
    (old / "locomotion_000001.npz").write_bytes(b"")                  # a file of the recorded run
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                # the record is there: no "no record" warning
        claim_folder(old, "locomotion", {"seed": 3, "model": None})               # the same run again: accepted
    with pytest.raises(ValueError, match=r"\(seed: 3 there, 4 now\)"):          # checked from now on
        claim_folder(old, "locomotion", {"seed": 4, "model": None})
    other = tmp_path / "other"                       # reach_far files are not older reach files (reach_* matched them)
    other.mkdir()
    (other / "reach_far_000000.npz").write_bytes(b"")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        claim_folder(other, "reach", {"seed": 0, "model": None})
    assert "preexisting" not in json.loads((other / "graspkit_make_reach.json").read_text())


def test_a_folder_takes_the_same_body_from_another_path(tmp_path, monkeypatch):
    """The record compared the model's absolute path beside its digest: the same file moved, or the folder extended
    on another machine, was refused. The digest decides now (another body is still refused, the test above)."""
    import shutil

    import pytest

    from graspkit.data.cli import claim_folder
    from graspkit.paths import default_model_path

    a, b = tmp_path / "a" / "m.npz", tmp_path / "b" / "m.npz"
    for p in (a, b):
        p.parent.mkdir()
        shutil.copy(default_model_path(), p)
    out = tmp_path / "clips"
    out.mkdir()
    claim_folder(out, "reach", {"seed": 7, "model": str(a)})
    claim_folder(out, "reach", {"seed": 7, "model": str(b)})
    monkeypatch.setenv("GRASPKIT_MODEL", str(b))
    claim_folder(out, "reach", {"seed": 7, "model": None})
    with pytest.raises(ValueError, match=r"seed: 7 there, 8 now"):
        claim_folder(out, "reach", {"seed": 8, "model": str(b)})


def test_wandr_reads_only_the_clips_of_each_folder_kind(tmp_path):
    """A reach clip written into locomotion/ (`data make --kind reach --out .../locomotion`) was listed among the
    locomotion clips, while MotionFill's reader skipped it; both take locomotion_*.npz there now (one's own names
    after the prefix too)."""
    import shutil

    from graspkit.data.wandr_dataset import list_clips
    from graspkit.paths import DATA_STUBS

    (tmp_path / "locomotion").mkdir()
    shutil.copy(DATA_STUBS / "motion" / "locomotion" / "locomotion_000000.npz", tmp_path / "locomotion")
    shutil.copy(DATA_STUBS / "motion" / "reach" / "reach_000000.npz", tmp_path / "locomotion")
    shutil.copy(DATA_STUBS / "motion" / "locomotion" / "locomotion_000001.npz",
                tmp_path / "locomotion" / "locomotion_000001_old.npz")
    assert [p.name for p in list_clips(tmp_path, kinds=("locomotion",))] == ["locomotion_000000.npz",
                                                                              "locomotion_000001_old.npz"]
