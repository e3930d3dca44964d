"""The ```python blocks of README.md and docs/*.md against the library: every name they import exists, and every
keyword they pass to a graspkit function or class is one of its parameters, and every name they read is defined
(checked, not run: the blocks run for minutes, and a few are sketches that say so)."""
import ast
import functools
import importlib
import inspect
import re
import typing
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def python_blocks(path: Path) -> list[str]:
    """The ```python fenced blocks of a Markdown file."""
    return re.findall(r"```python\n(.*?)```", path.read_text(), re.S)


def statements(block: str) -> list[ast.stmt]:
    """The block's statements (the blocks are valid Python: placeholders are `...`)."""
    return ast.parse(block).body


def names_in(stmts: list[ast.stmt]) -> dict[str, object]:
    """Import the names the statements import: {local name: object}."""
    names: dict[str, object] = {}
    for s in stmts:
        if isinstance(s, ast.ImportFrom):
            mod = importlib.import_module(s.module)
            for a in s.names:
                if hasattr(mod, a.name):
                    names[a.asname or a.name] = getattr(mod, a.name)
                else:                          # a submodule: `from graspkit import eval_saga`
                    names[a.asname or a.name] = importlib.import_module(f"{s.module}.{a.name}")
        elif isinstance(s, ast.Import):
            for a in s.names:
                names[a.asname or a.name.split(".")[0]] = importlib.import_module(a.name)
    return names


class Instance:
    """An object of a known graspkit class that a block made (`bm = BodyModel.from_file(...)`)."""

    def __init__(self, cls: type) -> None:
        self.cls = cls


def callee(func: ast.expr, names: dict[str, object]) -> object | None:
    """What a call's function names, when it is an imported graspkit name, an attribute of one, or a method of a
    variable whose type is known (see `returned_type`); else None."""
    if isinstance(func, ast.Name):
        obj = names.get(func.id)
        if isinstance(obj, Instance):                  # `bm(...)`: a module's forward, else __call__
            obj = getattr(obj.cls, "forward", None) or getattr(obj.cls, "__call__", None)
    elif isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) and func.value.id in names:
        owner = names[func.value.id]
        owner = owner.cls if isinstance(owner, Instance) else owner
        obj = getattr(owner, func.attr, None)
        assert obj is not None, f"{func.value.id}.{func.attr} does not exist ({owner})"
    else:
        return None
    return obj if getattr(obj, "__module__", "").startswith("graspkit") else None


def hint_namespace(obj: object) -> dict[str, object]:
    """The globals of obj's module plus the names its `if TYPE_CHECKING:` block imports (annotations only)."""
    module = inspect.getmodule(obj)
    return _module_hint_namespace(module.__name__) if module else {}


@functools.lru_cache(maxsize=None)
def _module_hint_namespace(name: str) -> dict[str, object]:
    """hint_namespace of one module, read and executed once."""
    module = importlib.import_module(name)
    ns = dict(vars(module))
    if getattr(module, "__file__", None):
        for node in ast.parse(Path(module.__file__).read_text()).body:
            if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
                exec(compile(ast.Module(node.body, type_ignores=[]), module.__file__, "exec"), ns)
    return ns


def returned_type(obj: object) -> type | None:
    """The graspkit class a function returns (its return annotation) or that a class call makes; else None."""
    if inspect.isclass(obj):
        return obj
    try:
        ret = typing.get_type_hints(obj, globalns=hint_namespace(obj)).get("return")
    except Exception:  # noqa: BLE001 - an annotation that does not resolve at run time
        return None
    return ret if inspect.isclass(ret) and ret.__module__.startswith("graspkit") else None


BLOCKS = [(p, i, b) for p in DOCS for i, b in enumerate(python_blocks(p))]


def test_the_docs_have_python_blocks():
    assert len(BLOCKS) >= 10 and {p.name for p, _, _ in BLOCKS} >= {"README.md", "wandr.md", "saga.md", "goal.md"}


@pytest.mark.parametrize("path,index,block", BLOCKS, ids=[f"{p.name}-{i}" for p, i, _ in BLOCKS])
def test_a_doc_block_names_what_the_library_has(path, index, block):
    stmts = statements(block)
    names = names_in(stmts)
    assert names, f"{path.name} block {index} imports nothing from graspkit"
    checked = 0
    for s in stmts:
        # `model = load_wandr(...)`: model.<method>(...) is checked too
        if (isinstance(s, ast.Assign) and len(s.targets) == 1 and isinstance(s.targets[0], ast.Name)
                and isinstance(s.value, ast.Call)):
            made = returned_type(callee(s.value.func, names))
            if made is not None:
                names[s.targets[0].id] = Instance(made)
        for node in ast.walk(s):
            if not isinstance(node, ast.Call):
                continue
            obj = callee(node.func, names)
            if obj is None:
                continue
            params = inspect.signature(obj).parameters
            if any(p.kind is p.VAR_KEYWORD for p in params.values()):
                continue
            for kw in node.keywords:
                assert kw.arg is None or kw.arg in params, (
                    f"{path.name} block {index}: {ast.unparse(node.func)}() has no parameter {kw.arg!r}")
            n_pos = sum(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in params.values()
                        if p.name != "self")
            if not any(p.kind is p.VAR_POSITIONAL for p in params.values()):
                assert len(node.args) <= n_pos, f"{path.name} block {index}: {ast.unparse(node)} has too many arguments"
            checked += 1
    assert checked, f"{path.name} block {index} calls no graspkit function this test can check"


USUAL = {"bm"}      # the setup every page assumes: a BodyModel `bm`


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_blocks_read_only_names_they_or_the_page_define(path):
    """Every name a block reads is defined by the block, a block before it on the page, a builtin or USUAL (imports included; a block
    in docs/saga_motion.md read `Gamma_bar`, `betas` and a file name no reader has, an independent check); a block
    that opens with a comment calling itself a sketch is exempt (it says where its inputs come from)."""
    import builtins

    defined = set(dir(builtins)) | USUAL
    for block in python_blocks(path):
        tree = ast.parse(block)
        assigned, loaded = set(), set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                assigned |= {(a.asname or a.name).split(".")[0] for a in node.names}
            elif isinstance(node, ast.Name):
                (assigned if isinstance(node.ctx, ast.Store) else loaded).add(node.id)
            elif isinstance(node, (ast.FunctionDef, ast.Lambda)):
                args = node.args
                assigned |= {a.arg for a in args.args + args.kwonlyargs + args.posonlyargs}
        if not block.lstrip().startswith("#") or "sketch" not in block.split("\n", 1)[0]:
            assert loaded <= defined | assigned, f"{path.name}: a block reads {sorted(loaded - defined - assigned)}"
        defined |= assigned
