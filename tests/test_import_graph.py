"""The package's import graph, read from the source with ``ast``: every import of an accd_gym
module, at module level or inside a function, absolute or relative, is an edge; the graph has no
cycle, every edge points down the layers of :data:`LAYERS` (docs/architecture.md draws them),
every edge ends at a module that exists, no module imports another module's private names (``_x``;
the ``_core`` extension module is the binding, not private), and an import of the package's own
modules inside a function says why it is deferred (an optional dependency or start-up time)."""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path
from typing import Optional

import accd_gym

PACKAGE_DIR = Path(accd_gym.__file__).parent
#: Modules that exist without a Python source of their own.
EXTENSIONS = {"accd_gym._core"}

#: The package's layers, bottom first: a module may import modules of its own layer and of the
#: layers below, never one above. A module belongs to the layer of the longest prefix that
#: names it (``accd_gym.envs.task`` is in "task", the rest of ``accd_gym.envs`` in "envs").
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("foundation", ("accd_gym._core", "accd_gym.errors", "accd_gym.files")),
    ("task", ("accd_gym.envs.task", "accd_gym.envs.config", "accd_gym.envs.overrides", "accd_gym.envs.tables",
              "accd_gym.envs.tiers", "accd_gym.envs.history")),
    ("control", ("accd_gym.control",)),
    ("envs", ("accd_gym.envs",)),
    ("learning", ("accd_gym.learning", "accd_gym.zoo")),
    ("evals", ("accd_gym.evals",)),
    ("applications", ("accd_gym.replays", "accd_gym.studies", "accd_gym.trained")),
    ("interface", ("accd_gym.cli", "accd_gym.__main__", "accd_gym")),
]
#: What a deferred import's comment starts with (on its line or the line above).
DEFERRED = "# deferred:"


def modules_of(root: Path, package: str) -> dict[str, Path]:
    """Every Python module under ``root`` (the folder of package ``package``) by dotted name."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join([package, *parts])] = path
    return out


def imports_of(name: str, path: Path, known: set[str]) -> list[tuple[str, str, int]]:
    """``(imported module, imported name or "", line)`` of every import in module ``name`` (file
    ``path``) of a module of the package; ``from P import n`` names module ``P.n`` when that is a
    module, else module ``P`` and name ``n``."""
    root = name.split(".")[0]
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == root or alias.name.startswith(root + "."):
                    out.append((alias.name, "", node.lineno))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = name.split(".") if is_package else name.split(".")[:-1]
                base_parts = package[: len(package) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            if base != root and not base.startswith(root + "."):
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in known:
                    out.append((sub, "", node.lineno))
                else:
                    out.append((base, alias.name, node.lineno))
    return out


def import_graph(root: Path, package: str, extensions: set[str] = frozenset()) -> dict[str, set[str]]:
    """Module -> the package's modules it imports, anywhere in its source."""
    mods = modules_of(root, package)
    known = set(mods) | set(extensions)
    return {name: {target for target, _, _ in imports_of(name, path, known)} - {name} for name, path in mods.items()}


def find_cycle(graph: dict[str, set[str]]) -> Optional[list[str]]:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None when it has none."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []

    def visit(node: str) -> Optional[list[str]]:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_the_package_has_no_import_cycle():
    graph = import_graph(PACKAGE_DIR, "accd_gym", EXTENSIONS)
    assert len(graph) > 30 and "accd_gym.envs.vector" in graph
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_every_import_names_an_existing_module_at_its_new_path():
    mods = modules_of(PACKAGE_DIR, "accd_gym")
    known = set(mods) | EXTENSIONS
    missing = [
        f"{path.relative_to(PACKAGE_DIR)}:{line}: {target}"
        for name, path in mods.items()
        for target, _, line in imports_of(name, path, known)
        if target not in known
    ]
    assert not missing, "imports of modules that do not exist (old paths?):\n" + "\n".join(missing)


def test_no_module_imports_a_private_name_of_another():
    mods = modules_of(PACKAGE_DIR, "accd_gym")
    known = set(mods) | EXTENSIONS
    bad = []
    for name, path in mods.items():
        for target, imported, line in imports_of(name, path, known):
            private = imported if imported else target.rsplit(".", 1)[-1]
            if not private.startswith("_") or private.startswith("__") or target in EXTENSIONS:
                continue
            if not imported and target.rsplit(".", 1)[0] == name:
                continue  # a package importing its own private submodule
            bad.append(f"{path.relative_to(PACKAGE_DIR)}:{line}: {target}{'.' + imported if imported else ''}")
    assert not bad, "private names imported across modules:\n" + "\n".join(bad)


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))


def test_the_checks_find_cycles_hidden_in_functions_and_relative_imports(tmp_path):
    pkg = tmp_path / "pkg"
    _write(pkg, {
        "__init__.py": "",
        "a/__init__.py": "",
        "a/low.py": "def f():\n    from ..b import high\n    return high\n",
        "a/mid.py": "from . import low\n",
        "b/__init__.py": "",
        "b/high.py": "from pkg.a.mid import low as _low\nfrom ..a import mid\n",
    })
    graph = import_graph(pkg, "pkg")
    assert graph["pkg.a.low"] == {"pkg.b.high"} and graph["pkg.a.mid"] == {"pkg.a.low"}
    assert graph["pkg.b.high"] == {"pkg.a.mid"}
    cycle = find_cycle(graph)
    assert cycle is not None and cycle[0] == cycle[-1] and set(cycle) == {"pkg.a.low", "pkg.a.mid", "pkg.b.high"}
    (pkg / "a" / "low.py").write_text("def f():\n    return 1\n")
    assert find_cycle(import_graph(pkg, "pkg")) is None


def test_the_real_graph_with_one_injected_back_edge_has_a_cycle():
    graph = import_graph(PACKAGE_DIR, "accd_gym", EXTENSIONS)
    assert "accd_gym.envs.task" in graph["accd_gym.envs.vector"]
    graph["accd_gym.envs.task"] = graph["accd_gym.envs.task"] | {"accd_gym.envs.vector"}
    assert find_cycle(graph) is not None


def test_the_private_name_check_sees_private_imports(tmp_path):
    pkg = tmp_path / "pkg"
    _write(pkg, {"__init__.py": "", "x.py": "def _h():\n    pass\n", "y.py": "def g():\n    from .x import _h\n"})
    known = set(modules_of(pkg, "pkg"))
    assert ("pkg.x", "_h", 2) in imports_of("pkg.y", pkg / "y.py", known)


# -- layers -----------------------------------------------------------------------------------

def layer_of(module: str, layers: list[tuple[str, tuple[str, ...]]] = LAYERS) -> int:
    """The index in ``layers`` of the layer whose longest prefix names ``module``."""
    best, best_len = None, -1
    for index, (_, prefixes) in enumerate(layers):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    if best is None:
        raise KeyError(f"{module} is in no layer")
    return best


def upward_edges(graph: dict[str, set[str]], layers: list[tuple[str, tuple[str, ...]]] = LAYERS) -> list[str]:
    """Every edge of ``graph`` from a module to one in a higher layer, as text."""
    out = []
    for src, targets in sorted(graph.items()):
        for dst in sorted(targets):
            a, b = layer_of(src, layers), layer_of(dst, layers)
            if b > a:
                out.append(f"{src} ({layers[a][0]}) -> {dst} ({layers[b][0]})")
    return out


def test_every_import_points_down_the_layers():
    graph = import_graph(PACKAGE_DIR, "accd_gym", EXTENSIONS)
    for module in graph:
        layer_of(module)  # every module has a layer
    bad = upward_edges(graph)
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_the_layer_check_finds_an_injected_upward_import():
    graph = import_graph(PACKAGE_DIR, "accd_gym", EXTENSIONS)
    assert layer_of("accd_gym.envs.task") < layer_of("accd_gym.control.lqr") < layer_of("accd_gym.envs.residual")
    assert layer_of("accd_gym") > layer_of("accd_gym.replays.recording")
    graph["accd_gym.envs.vector"] = graph["accd_gym.envs.vector"] | {"accd_gym.evals.episodes"}
    assert upward_edges(graph) == ["accd_gym.envs.vector (envs) -> accd_gym.evals.episodes (evals)"]


def test_the_layer_check_sees_upward_imports_in_functions(tmp_path):
    pkg = tmp_path / "pkg"
    _write(pkg, {
        "__init__.py": "",
        "low/__init__.py": "",
        "low/a.py": "def f():\n    from pkg.high import b\n    return b\n",
        "high/__init__.py": "",
        "high/b.py": "from ..low import a\n",
    })
    layers = [("low", ("pkg.low",)), ("high", ("pkg.high", "pkg"))]
    graph = import_graph(pkg, "pkg")
    assert upward_edges(graph, layers) == ["pkg.low.a (low) -> pkg.high.b (high)"]
    (pkg / "low" / "a.py").write_text("X = 1\n")
    assert upward_edges(import_graph(pkg, "pkg"), layers) == []


# -- imports inside functions -----------------------------------------------------------------

def deferred_imports(name: str, path: Path) -> list[tuple[int, bool]]:
    """``(line, has its reason)`` of every import of the package's own modules inside a function
    of module ``name``: the reason is a :data:`DEFERRED` comment on the import's line or on the
    line above the block of import lines it is in."""
    root = name.split(".")[0]
    lines = path.read_text().splitlines()
    out = []
    for fn in ast.walk(ast.parse("\n".join(lines), str(path))):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            own = (isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").split(".")[0] == root)) or (
                isinstance(node, ast.Import) and any(a.name.split(".")[0] == root for a in node.names))
            if own:
                above = node.lineno - 2
                while above >= 0 and lines[above].strip().startswith(("from ", "import ")):
                    above -= 1
                reason = above >= 0 and lines[above].strip().startswith(DEFERRED)
                out.append((node.lineno, DEFERRED in lines[node.lineno - 1] or reason))
    return sorted(set(out))


def test_every_import_inside_a_function_says_why_it_is_deferred():
    mods = modules_of(PACKAGE_DIR, "accd_gym")
    found = {name: deferred_imports(name, path) for name, path in mods.items()}
    assert sum(len(v) for v in found.values()) < 60  # the few an optional dependency or start-up needs
    bad = [f"{mods[name].relative_to(PACKAGE_DIR)}:{line}" for name, v in found.items() for line, ok in v if not ok]
    assert not bad, f"imports inside functions without a {DEFERRED!r} comment:\n" + "\n".join(bad)


def test_the_deferred_import_check_sees_one_without_a_reason(tmp_path):
    pkg = tmp_path / "pkg"
    _write(pkg, {"__init__.py": "", "m.py": (
        "def f():\n    from pkg import n\n\n"
        "def g():\n    # deferred: start-up time\n    from pkg import n\n\n"
        "def h():\n    import json\n\n"
        "def k():\n    # deferred: start-up time\n    from pkg import n\n    from pkg import o\n    x = 1\n    from pkg import p\n")})
    assert deferred_imports("pkg.m", pkg / "m.py") == [(2, False), (6, True), (13, True), (14, True), (16, False)]
