"""Build the lessons: notebooks/src/NN_name.py (percent format) -> notebooks/NN_name.ipynb, executed in place.

    python tools/notebooks.py            # build and execute every lesson
    python tools/notebooks.py 01 02      # only lessons whose name starts with these prefixes
    python tools/notebooks.py --check    # fail if an .ipynb's code/markdown differs from its source

A source file is Python with cells separated by `# %%` lines; `# %% [markdown]` starts a markdown cell
whose lines are comments (`# ` stripped). The executed notebook keeps its outputs, which nbval compares.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
SRC, OUT = ROOT / "notebooks" / "src", ROOT / "notebooks"


def parse_cells(text: str) -> list[tuple[str, str]]:
    """Split a percent-format source into (kind, source) cells, kind in {'code', 'markdown'}."""
    cells, kind, lines = [], None, []
    for line in text.splitlines():
        if line.startswith("# %%"):
            if kind is not None:
                cells.append((kind, "\n".join(lines).strip("\n")))
            kind, lines = ("markdown" if "[markdown]" in line else "code"), []
        elif kind == "markdown":
            lines.append(line[2:] if line.startswith("# ") else line.lstrip("#"))
        elif kind is not None:
            lines.append(line)
    if kind is not None:
        cells.append((kind, "\n".join(lines).strip("\n")))
    return [c for c in cells if c[1]]


def to_notebook(src: Path) -> nbformat.NotebookNode:
    """A notebook (no outputs) from a percent-format source file."""
    nb = nbformat.v4.new_notebook()
    nb.metadata = {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"},
                   "language_info": {"name": "python"}}
    new = {"code": nbformat.v4.new_code_cell, "markdown": nbformat.v4.new_markdown_cell}
    nb.cells = [new[k](s) for k, s in parse_cells(src.read_text())]
    for i, c in enumerate(nb.cells):
        c["id"] = f"cell-{i:03d}"  # stable ids keep diffs small
    return nb


def build(src: Path, timeout: int = 600) -> float:
    """Convert and execute one lesson in place (atomically); returns the run time in seconds."""
    nb = to_notebook(src)
    os.environ.setdefault("MPLBACKEND", "Agg")
    t0 = time.perf_counter()
    NotebookClient(nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(OUT)}}).execute()
    dt = time.perf_counter() - t0
    for c in nb.cells:
        c.get("metadata", {}).pop("execution", None)
    dst = OUT / (src.stem + ".ipynb")
    tmp = dst.with_suffix(".ipynb.tmp")
    nbformat.write(nb, tmp)
    os.replace(tmp, dst)
    return dt


def check(src: Path) -> bool:
    """Whether the committed .ipynb has the same cells as its source."""
    dst = OUT / (src.stem + ".ipynb")
    if not dst.exists():
        return False
    a = [(c.cell_type, c.source) for c in nbformat.read(dst, as_version=4).cells]
    return a == [(c.cell_type, c.source) for c in to_notebook(src).cells]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("prefixes", nargs="*")
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    srcs = sorted(p for p in SRC.glob("[0-9][0-9]_*.py") if not args.prefixes or p.name.startswith(tuple(args.prefixes)))
    if args.check:
        stale = [p.name for p in srcs if not check(p)]
        print("stale: " + ", ".join(stale) if stale else f"{len(srcs)} notebooks match their sources")
        return 1 if stale else 0
    for p in srcs:
        print(f"{p.stem}: {build(p):.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
