"""Every lesson's .ipynb has the cells of its source in notebooks/src (so the docs never drift)."""
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("nbtools", ROOT / "tools" / "notebooks.py")
nbtools = importlib.util.module_from_spec(spec)
spec.loader.exec_module(nbtools)
SOURCES = sorted((ROOT / "notebooks" / "src").glob("[0-9][0-9]_*.py"))


def test_parse_cells_splits_markdown_and_code():
    cells = nbtools.parse_cells("# %% [markdown]\n# # Title\n# text\n\n# %%\nx = 1\n# %%\n\n")
    assert cells == [("markdown", "# Title\ntext"), ("code", "x = 1")]


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_notebook_matches_its_source(src):
    assert nbtools.check(src), f"{src.name}: run `python tools/notebooks.py {src.name[:2]}` to rebuild the notebook"
