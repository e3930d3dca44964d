"""Every method on the same objects and goals (graspkit.benchmark), as ratios against references measured in the
same run: grasp metrics against the synthetic ground truth, motion metrics against the procedural planner, and
against the papers' published figures (their data, their code: a reference point, not a target).

Run: python benchmarks/all_methods.py [--quick] [--data FOLDER ...] [--out outputs/benchmark]
     python benchmarks/all_methods.py --csv docs/benchmark/benchmark.csv   # a finished report's table, no rerun
Runs every method again (graspkit.benchmark.run_all) and prints the benchmark table, then the ratio tables and each
method's wall time; --csv reads the rows of a benchmark.csv instead.
"""
from __future__ import annotations

import argparse
import os
import math
from pathlib import Path

from graspkit.benchmark import GRASP_METRICS, MOTION_METRICS, Row, markdown, read_csv, run_all, write_report


def ratio_table(rows: list[Row], table: str, reference: str) -> str:
    """Markdown: each graspkit row's metric divided by the `reference` row's (same table)."""
    metrics = GRASP_METRICS if table == "grasp" else MOTION_METRICS
    ours = [r for r in rows if r.table == table and r.source == "graspkit"]
    ref = next((r for r in ours if r.method == reference), None)
    if ref is None or not ref.values:
        return f"(no {reference!r} row to compare with)"
    cols = [k for k in metrics if k in ref.values]
    lines = [f"| {table}: method / {reference} | " + " | ".join(metrics[k][0] for k in cols) + " |",
             "|---|" + "---|" * len(cols)]
    if table == "motion":        # the planner's row is its own protocol (its 40 clips): a scale, not a like-for-like
        lines.insert(0, f"(each row against {reference!r}, which is measured on other clips: a scale across "
                        "protocols, not a comparison; compare a column's cells within one protocol, README)\n")
    for r in ours:
        if r is ref or not r.values:
            continue
        cells = []
        for k in cols:
            a, b = r.values.get(k), ref.values[k]
            cells.append("—" if a is None else f"{a / b:.2f}×" if b else "= 0" if not a else f"{a:.3g} (ref 0)")
        lines.append(f"| {r.method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


# the papers' ground truth is captured data; ours is synthetic (grasps) or the planner's (motion)
COUNTERPART = {("grasp", "ground truth (GRAB)"): "ground truth (synthetic)",
               ("motion", "ground truth (GRAB)"): "procedural planner (approach clips)"}


def paper_ratio_table(rows: list[Row]) -> str:
    """Markdown: ours / the paper's figure, for every (method, metric) that both give."""
    lines = ["| method (ours vs paper) | metric | ours | paper | source | ours / paper |", "|---|---|---|---|---|---|"]
    ours = {(r.table, r.method): r for r in rows if r.source == "graspkit"}
    for p in rows:
        if p.source == "graspkit":
            continue
        o = ours.get((p.table, COUNTERPART.get((p.table, p.method), p.method)))
        for k, v in p.values.items():
            if o is None or k not in o.values:
                continue
            q = o.values[k] / v if v else math.inf
            name = o.method if o.method == p.method else f"{o.method} vs {p.method}"
            lines.append(f"| {name} | {k} | {o.values[k]:.3g} | {v:g} | {p.source} | {q:.2f}× |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--data", type=Path, action="append", default=None)
    ap.add_argument("--out", type=Path, default=Path("outputs/benchmark"))
    ap.add_argument("--csv", type=Path, default=None, help="a benchmark.csv to print as ratios (nothing is run)")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}")
    if args.csv is not None:
        if not args.csv.is_file():
            ap.error(f"--csv: no file {args.csv}")
        rows = read_csv(args.csv)
    else:
        rows = run_all(args.out, data=args.data, quick=args.quick)
        write_report(rows, args.out)
    print(markdown(rows))
    print(ratio_table(rows, "grasp", "ground truth (synthetic)"), "\n")
    print(ratio_table(rows, "motion", "procedural planner (approach clips)"), "\n")
    print(paper_ratio_table(rows), "\n")
    print("| method | note (count; wall time) |\n|---|---|")
    for r in rows:
        if r.source == "graspkit":
            print(f"| {r.method} | {r.note} |")


if __name__ == "__main__":
    main()
