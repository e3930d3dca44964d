"""GOAL Tab. 2 over training seeds: MNet and its three ablations (GOAL §4.2, Tab. 2) trained with each seed, the same
epochs, no time limit, and every row's teacher-forced V2V (mm) given as mean ± sd over the seeds, with MNet's paired
difference to each ablation (the same seed: the same data order and initialisation draw). One run of Tab. 2 cannot
say whether MNet is below an ablation when they are a fraction of a millimetre apart; the seeds' spread can.

    graspkit data make --kind approach --n 272 --seed 0
    python tools/goal_tab2_seeds.py --out /tmp/tab2_seeds --seeds 0 1 2 3 4 --jobs 2 \
        --json data_stubs/checkpoints/goal_tab2_seeds.json       # 29 min on two cores (the shipped JSON)

Checkpoints go to <out>/seed<S>/mnet[_<variant>].pt (one already there is measured, not trained again) and resumable
runs to <out>/runs; each training runs on one thread, `--jobs` of them at a time. docs/goal.md ("Tab. 2 over seeds")
gives the figures of the shipped JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import sys
import threading
import time
from multiprocessing import get_context
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:                       # run from a clone without an install
    sys.path.insert(0, str(ROOT))

# longest first, so two jobs finish together
ORDER = ("mnet", "no_iaa", "pose", "1frame")


def checkpoint(out: Path, seed: int, variant: str) -> Path:
    """<out>/seed<S>/mnet.pt or mnet_<variant>.pt (the names tab2_results reads)."""
    return out / f"seed{seed}" / ("mnet.pt" if variant == "mnet" else f"mnet_{variant}.pt")


def _train(folders: list[str], out: str, seed: int, variant: str, epochs: int) -> tuple[int, str, float]:
    """One training on one thread (a worker process): (seed, variant, seconds)."""
    import torch

    from graspkit.eval_goal import run_train_mnet

    torch.set_num_threads(1)
    path = checkpoint(Path(out), seed, variant)
    path.parent.mkdir(parents=True, exist_ok=True)
    info = run_train_mnet([Path(f) for f in folders], path, variant, epochs, None, seed, threads=1,
                          run_dir=Path(out) / "runs", progress=False)
    return seed, variant, info["seconds"]


def _measure(folders: list[str], out: str, seed: int, stride: int) -> tuple[int, dict]:
    """Tab. 2 of one seed's checkpoints on one thread (a worker process): (seed, tab2_results' dict), kept in
    <out>/seed<S>/tab2.json with a key of the checkpoints, data, stride and graspkit's sources, and read from there
    while they hold."""
    import torch

    from graspkit.eval_goal import TAB2_ROWS, tab2_results
    from graspkit.paths import write_atomic
    from graspkit.train import code_version, file_key, files_key

    folder = Path(out) / f"seed{seed}"
    key = {"checkpoints": {f: file_key(folder / f) for f in TAB2_ROWS}, "data": files_key(folders), "stride": stride,
           "code": code_version()}                    # the evaluator's code too
    cache = folder / "tab2.json"
    if cache.is_file():
        kept = json.loads(cache.read_text())
        if kept.get("key") == key:
            return seed, kept["result"]
    torch.set_num_threads(1)
    res = tab2_results([Path(f) for f in folders], folder, stride)
    res["tab2"] = {r: {p: float(x) for p, x in row.items()} for r, row in res["tab2"].items()}   # plain floats: JSON
    write_atomic(cache, json.dumps({"key": key, "result": res}, indent=1) + "\n")
    return seed, res


def _call(job: tuple) -> tuple:
    """(i, fn(*args)) for job (i, fn, args): a pool task that keeps its place."""
    i, fn, args = job
    return i, fn(*args)


def _map(fn, calls: list[tuple], jobs: int, done=None) -> list:
    """[fn(*c) for c in calls], in `jobs` spawned processes when jobs > 1 (results in the calls' order); done(result)
    is called as each finishes. The workers are terminated when the parent stops early (an error, Ctrl-C, or a
    SIGTERM, which exits with 143 meanwhile): a pool left running had trained on beside the next run."""
    done = done or (lambda r: None)
    if jobs == 1 or len(calls) < 2:
        out = []
        for c in calls:
            out.append(fn(*c))
            done(out[-1])
        return out
    results: dict[int, object] = {}
    main = threading.current_thread() is threading.main_thread()
    before = signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum)) if main else None
    try:
        with get_context("spawn").Pool(jobs) as pool:          # __exit__ terminates the workers
            for i, r in pool.imap_unordered(_call, [(i, fn, c) for i, c in enumerate(calls)]):
                results[i] = r
                done(r)
    finally:
        if main:
            signal.signal(signal.SIGTERM, before)
    return [results[i] for i in range(len(calls))]


def summarise(per_seed: dict[int, dict]) -> dict:
    """{row: {part: {'mean', 'sd', 'seeds'}}} and MNet's paired differences {ablation: {part: {'mean', 'sd',
    'below', 'p'}}} ('below': seeds on which MNet's error is the lower; 'p': the paired t-test's two-sided p over the
    seeds, scipy) from {seed: {row: {part: mm}}}."""
    from scipy.stats import ttest_rel

    from graspkit.eval_goal import TAB2_ROWS

    seeds = sorted(per_seed)
    rows = [r for r in TAB2_ROWS.values() if any(r in per_seed[s] for s in seeds)]     # MNet first, as in Tab. 2
    stats, paired = {}, {}
    for r in rows:
        stats[r] = {}
        for part in ("body", "hand", "feet"):
            v = [per_seed[s][r][part] for s in seeds if r in per_seed[s]]
            stats[r][part] = {"mean": statistics.fmean(v), "sd": statistics.stdev(v) if len(v) > 1 else 0.0,
                              "seeds": v}
    for r in rows[1:]:
        both = [s for s in seeds if "MNet" in per_seed[s] and r in per_seed[s]]
        if not both:
            continue
        paired[r] = {}
        for part in ("body", "hand", "feet"):
            m, o = [per_seed[s]["MNet"][part] for s in both], [per_seed[s][r][part] for s in both]
            d = [x - y for x, y in zip(m, o)]
            p = float(ttest_rel(m, o).pvalue) if len(d) > 2 else None
            paired[r][part] = {"mean": statistics.fmean(d), "sd": statistics.stdev(d) if len(d) > 1 else 0.0,
                               "below": int(sum(x < 0 for x in d)), "seeds": len(d), "p": p}
    return {"rows": stats, "mnet_minus": paired}


def table(summary: dict) -> str:
    """The summary as a markdown table (mean ± sd over the seeds, then MNet − row paired, the paired t-test's p)."""
    lines = ["| row | body | hand | feet | MNet − row: body | hand | feet |", "|---|---|---|---|---|---|---|"]
    for r, st in summary["rows"].items():
        cells = [f"{st[p]['mean']:.2f} ± {st[p]['sd']:.2f}" for p in ("body", "hand", "feet")]
        d = summary["mnet_minus"].get(r)
        cells += ([f"{d[p]['mean']:+.2f} ± {d[p]['sd']:.2f} ({d[p]['below']}/{d[p]['seeds']} below"
                   + (f", p {d[p]['p']:.2g})" if d[p]["p"] is not None else ")") for p in ("body", "hand", "feet")]
                  if d else ["—"] * 3)
        lines.append(f"| {r} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def trained_with(path: Path) -> dict:
    """What a checkpoint of run_train_mnet says of its training: {'variant', 'epochs', 'seconds', ...}."""
    from graspkit.train import load_checkpoint

    return load_checkpoint(path).get("extra", {})


def _made(folder: str) -> dict:
    """How a data folder was made (its graspkit_make_*.json: kind, n, seed...), or its name when it has none."""
    made = sorted(Path(folder).glob("graspkit_make_*.json"))
    if not made:
        return {"folder": Path(folder).name}
    m = json.loads(made[0].read_text())
    files = len(list(Path(folder).glob("*.npz")))
    return {k: m[k] for k in ("kind", "seed", "chunk", "body") if k in m} | {"files": files}


def main(argv: list[str] | None = None) -> int:
    from graspkit.eval_goal import default_data_folders
    from graspkit.paths import write_atomic
    from graspkit.train import files_key

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="folder for the seeds' checkpoints and runs")
    p.add_argument("--data", type=Path, action="append", default=None,
                   help="approach folder (repeatable; default: the data-make cache)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--epochs", type=int, default=12)
    p.add_argument("--jobs", type=int, default=2, help="trainings (and measurements) at a time, one thread each")
    p.add_argument("--window-stride", type=int, default=5)
    p.add_argument("--json", type=Path, default=None, help="write the per-seed rows and the summary here")
    a = p.parse_args(argv)
    if a.epochs < 1 or a.jobs < 1 or a.window_stride < 1:
        p.error("--epochs, --jobs and --window-stride: expected positive integers")
    if len(set(a.seeds)) != len(a.seeds):
        p.error(f"--seeds: expected distinct seeds, got {a.seeds}")
    folders = [str(f) for f in (a.data or default_data_folders())]
    os.environ["OMP_NUM_THREADS"] = "1"                 # the workers' BLAS, before they start
    t0 = time.perf_counter()
    todo = [(s, v) for v in ORDER for s in a.seeds if not checkpoint(a.out, s, v).is_file()]
    data = files_key(folders)
    for s, v in [(s, v) for v in ORDER for s in a.seeds if (s, v) not in todo]:   # found: trained as asked?
        try:
            got = trained_with(checkpoint(a.out, s, v))
        except ValueError as e:
            p.error(f"--out: {e}")
        asked = {"variant": v, "epochs": a.epochs, "seed": s, "files": data}
        legacy = ("seed", "files")                   # recorded since 2026-12-07: older checkpoints pass on these
        off = [k for k in asked if (k in got or k not in legacy) and got.get(k) != asked[k]]
        if off:
            p.error(f"--out: {checkpoint(a.out, s, v)} was trained with other "
                    + ", ".join(f"{k} ({got.get(k)!r}, expected {asked[k]!r})" for k in off)
                    + " (remove it to train it again)")
    done: list = []

    def trained(r: tuple[int, str, float]) -> None:
        done.append(r)
        print(f"trained {r[1]} seed {r[0]} in {r[2]:.0f} s ({len(done)} of {len(todo)})", flush=True)

    _map(_train, [(folders, str(a.out), s, v, a.epochs) for s, v in todo], a.jobs, trained)
    measured = dict(_map(_measure, [(folders, str(a.out), s, a.window_stride) for s in a.seeds], a.jobs))
    per_seed = {s: measured[s]["tab2"] for s in a.seeds}
    summary = summarise(per_seed)
    print(table(summary))
    if a.json:
        res = {"per_seed": {str(s): per_seed[s] for s in a.seeds}, **summary,
               "windows": measured[a.seeds[0]]["tab2_windows"], "window_stride": a.window_stride,
               "epochs": a.epochs, "seeds": a.seeds,
               "train_seconds": {f"seed{s}/{v}": trained_with(checkpoint(a.out, s, v))["seconds"]
                                 for s in a.seeds for v in ORDER},
               "seconds": time.perf_counter() - t0, "data": [_made(f) for f in folders],
               "protocol": "teacher-forced: from the true past 5 frames the next 10 (1 for the 1-frame model, "
                           "rolled out) predicted; V2V mm over the test clips' windows",
               "command": "python tools/goal_tab2_seeds.py " + " ".join(argv if argv is not None else sys.argv[1:])}
        write_atomic(a.json, json.dumps(res, indent=1) + "\n")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
