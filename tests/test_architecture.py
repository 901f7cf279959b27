"""The house rules, read from the code: imports go one way (no cycles, function-level
imports included), no package takes another's private names, the Morse package
stands alone, and no function outside generated code runs past 60 lines."""

import ast
from pathlib import Path

import pytest

import volseg

#: The repository (pipelines/, data_fetch/) and the package as imported (the working
#: tree, or an installed wheel).
ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(volseg.__file__).resolve().parent
#: Generated code (the curvature stencils, written by `_stencil_codegen`).
GENERATED = {"volseg.curvature._grid_stencil"}
MAX_FUNCTION_LINES = 60


def _module_name(path: Path) -> str:
    base = PACKAGE.parent if path.is_relative_to(PACKAGE) else ROOT
    parts = path.relative_to(base).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict:
    return {_module_name(p): p for p in PACKAGE.rglob("*.py")}


MODULES = _modules()
assert len(MODULES) > 50 and "volseg.morse._build" in MODULES, sorted(MODULES)[:5]


def _resolve(module: str, path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    for _ in range(node.level - 1):
        package = package.rsplit(".", 1)[0]
    return f"{package}.{node.module}" if node.module else package


def _imports(module: str):
    """(imported module, imported name or None, line) for every volseg import of
    `module`, at any depth (function-level imports included)."""
    path = MODULES[module]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("volseg"):
                    yield alias.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(module, path, node)
            if not target.startswith("volseg"):
                continue
            for alias in node.names:
                submodule = f"{target}.{alias.name}"
                if submodule in MODULES:
                    yield submodule, None, node.lineno
                else:
                    yield target, alias.name, node.lineno


def _package_of(module: str) -> str:
    """The unit that owns a module: volseg's subpackage, or the top-level module."""
    parts = module.split(".")
    if len(parts) >= 2 and f"volseg.{parts[1]}" in MODULES and \
            MODULES[f"volseg.{parts[1]}"].name == "__init__.py":
        return f"volseg.{parts[1]}"
    return module


#: Public leaves: what every package may raise or warn with.
PUBLIC_LEAVES = {"volseg.errors"}


def _is_leaf(module: str) -> bool:
    """A shared leaf: a private top-level module (or one of `PUBLIC_LEAVES`) that
    imports nothing of volseg but other leaves (checked by
    `test_leaves_import_only_leaves`)."""
    name = module.split(".")
    return module in PUBLIC_LEAVES or (
        len(name) == 2 and name[1].startswith("_") and not name[1].startswith("__")
        and _package_of(module) == module)


def _graph() -> dict:
    graph = {}
    for module in MODULES:
        graph[module] = set()
        for target, _, _ in _imports(module):
            if target in MODULES and target != module and target != "volseg":
                graph[module].add(target)
    return graph


def test_imports_have_no_cycle():
    graph = _graph()
    state, path = {}, []

    def visit(module):
        state[module] = "open"
        path.append(module)
        for target in sorted(graph.get(module, ())):
            if state.get(target) == "open":
                cycle = path[path.index(target):] + [target]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if target not in state:
                visit(target)
        path.pop()
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module)


def test_no_private_name_is_imported_across_packages():
    offences = []
    for module in MODULES:
        own = _package_of(module)
        for target, name, line in _imports(module):
            if target not in MODULES or _package_of(target) == own or _is_leaf(target):
                continue
            private_module = any(part.startswith("_") and not part.startswith("__")
                                 for part in target.split(".")[1:])
            private_name = name is not None and name.startswith("_") and not name.startswith("__")
            if private_module or private_name:
                offences.append(f"{module}:{line} imports {target}"
                                + (f".{name}" if name else ""))
    assert not offences, "\n".join(offences)


def test_leaves_import_only_leaves():
    for module in MODULES:
        if _is_leaf(module):
            for target, _, line in _imports(module):
                assert target == "volseg" or _is_leaf(target), f"{module}:{line} imports {target}"


def test_morse_stands_alone():
    """The Morse package imports nothing of volseg outside itself and the leaves, so
    it can be lifted out with them."""
    for module in MODULES:
        if _package_of(module) != "volseg.morse":
            continue
        for target, _, line in _imports(module):
            assert _package_of(target) == "volseg.morse" or _is_leaf(target), \
                f"{module}:{line} imports {target}"


def _top_level_imports(module: str):
    """(imported module, line) of `module`'s imports outside any function."""
    path = MODULES[module]
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, path, node)
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                yield (sub if sub in MODULES else target), node.lineno
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno


def test_the_in_memory_morse_stage_never_loads_the_distributed_build():
    """`volseg.morse` outside `volseg.morse.blocks` imports neither Dask nor the
    distributed build at module level (a Dask field reaches them inside the call)."""
    offences = []
    for module in MODULES:
        if _package_of(module) != "volseg.morse" or module.startswith("volseg.morse.blocks"):
            continue
        for target, line in _top_level_imports(module):
            if target.startswith(("volseg.morse.blocks", "dask", "distributed")):
                offences.append(f"{module}:{line} imports {target}")
    assert not offences, "\n".join(offences)


def test_descending_complex_on_numpy_imports_no_dask():
    import subprocess
    import sys

    code = ("import sys, numpy as np\n"
            "from volseg.morse import descending_complex\n"
            "h = descending_complex(np.random.default_rng(0).random((9, 8, 7)))\n"
            "h.segment(n_regions=3); h.segment(n_regions=3, measure='hypervolume')\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'dask', 'distributed'}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


#: How a measure's name would be compared to a literal: ``== "size"``, ``in ("size", ...)``,
#: ``"size" in measures``, ``.measure != 'persistence'``.
_NAMES = "(persistence|size|hypervolume|height|area|volume)"
_COMPARED = [rf"[=!]=\s*['\"]{_NAMES}['\"]", rf"['\"]{_NAMES}['\"]\s*[=!]=",
             rf"(not\s+)?in\s*[(\[{{]\s*(None,\s*)?['\"]{_NAMES}['\"]",
             rf"['\"]{_NAMES}['\"]\s+(not\s+)?in\s+\w*measure"]


def test_no_module_compares_measure_names():
    """A measure is a registry entry (`volseg.morse.MEASURE_REGISTRY`): code asks the
    entry (``get_measure(m).pruned``), never compares the name to a literal."""
    import re

    offences = []
    for module, path in MODULES.items():
        for number, line in enumerate(path.read_text().splitlines(), 1):
            code = line.split("#")[0]
            if any(re.search(pattern, code) for pattern in _COMPARED):
                offences.append(f"{module}:{number}: {line.strip()}")
    assert not offences, "\n".join(offences)


def test_the_measure_search_finds_a_comparison():
    import re

    planted = ['if measure == "persistence":', "if cut.measure != 'size':",
               'x = m in ("persistence", "size")', 'if "hypervolume" in measures:']
    for line in planted:
        assert any(re.search(p, line) for p in _COMPARED), line
    assert not any(re.search(p, 'measure = PERSISTENCE.name') for p in _COMPARED)


def _code_lines(lines, node) -> int:
    body = node.body
    doc = None
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        doc = range(body[0].lineno, body[0].end_lineno + 1)
    return sum(1 for n in range(node.lineno, node.end_lineno + 1)
               if lines[n - 1].strip() and not lines[n - 1].strip().startswith("#")
               and (doc is None or n not in doc))


@pytest.mark.parametrize("root", ["volseg", "pipelines", "data_fetch"])
def test_no_function_is_over_60_code_lines(root):
    long = []
    folder = PACKAGE if root == "volseg" else ROOT / root
    paths = sorted(folder.rglob("*.py"))
    assert paths, folder
    for path in paths:
        if _module_name(path) in GENERATED:
            continue
        source = path.read_text()
        lines = source.splitlines()
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                count = _code_lines(lines, node)
                if count > MAX_FUNCTION_LINES:
                    long.append(f"{_module_name(path)}:{node.lineno} {node.name}: {count}")
    assert not long, "\n".join(long)


def test_the_rules_see_a_cycle_and_a_private_import(tmp_path):
    """The checks above can fail: a planted cycle and a planted private import are
    found by the same functions."""
    a = ast.parse("from .b import x\n")
    assert _resolve("volseg.a", PACKAGE / "a.py", a.body[0]) == "volseg.b"
    nested = ast.parse("from ..morse import _edges\n")
    assert _resolve("volseg.blockwise._storage", PACKAGE / "blockwise" / "_storage.py",
                    nested.body[0]) == "volseg.morse"
    assert _package_of("volseg.morse._edges") == "volseg.morse"
    assert _is_leaf("volseg._kuhn") and not _is_leaf("volseg.morse._kernels")
    assert not _is_leaf("volseg.segment")


def test_pipelines_use_only_public_volseg_names():
    """The batch pipelines are volseg's first users: public names and leaves only."""
    offences = []
    for path in sorted((ROOT / "pipelines").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("volseg"):
                for alias in node.names:
                    submodule = f"{node.module}.{alias.name}"
                    target = submodule if submodule in MODULES else node.module
                    name = None if submodule in MODULES else alias.name
                    private = any(p.startswith("_") for p in target.split(".")[1:]) or (
                        name is not None and name.startswith("_"))
                    if private and not _is_leaf(target):
                        offences.append(f"{path.name}:{node.lineno} imports {target}"
                                        + (f".{name}" if name else ""))
    assert not offences, "\n".join(offences)


def test_every_design_reference_resolves_inside_the_repository():
    """Code cites the contract as "docs/design.md section N": the file is in the
    repository and has that section."""
    import re

    design = ROOT / "docs" / "design.md"
    if not design.exists():
        pytest.skip("run from the repository (the wheel's test copy has no docs/)")
    sections = {int(n) for n in re.findall(r"^## (\d+)\.", design.read_text(), re.M)}
    assert sections == set(range(1, 14)), sorted(sections)
    missing = []
    for path in [*PACKAGE.rglob("*.py"), *(ROOT / "tests").rglob("*.py")]:
        text = path.read_text()
        assert "DESIGN" + ".md" not in text, path           # the old, outside file
        for match in re.finditer(r"design\.md,? sections? (\d+)(?: and (\d+))?", text):
            missing += [f"{path.name}: section {n}" for n in match.groups()
                        if n and int(n) not in sections]
    assert not missing, missing
