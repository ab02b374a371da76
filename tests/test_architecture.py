"""The project's layers, checked on the source (no import is executed).

``mappers`` is arrays in, maps out: it never imports ``gymnasium``, ``gym``, ``pygame`` or
``lfmdr_gym``, so it serves logged data as well as the simulator; ``lfmdr_gym`` builds on it.
Within each of the two packages the modules import one another without cycles, and no module
is over :data:`MAX_LINES` lines.

Every import is read with :mod:`ast`, wherever it is written: at module level, inside a function
or a method, under ``if TYPE_CHECKING:`` (a dependency there is still one of the design; to break
a cycle, move the code, do not hide the import), and ``importlib.import_module("...")`` /
``__import__("...")`` with a literal name.

The import graph (a node per module; a package is the node of its ``__init__.py``):

* Relative imports are resolved against the importer's package (an ``__init__.py`` is its own
  package).
* ``import a.b.c`` and ``from a.b.c import name`` import the module ``a.b.c``; ``from a.b import
  c``, when ``a.b.c`` is a module of the tree, imports the sub-module ``a.b.c`` (not ``a.b``'s
  attribute).
* Importing a module also runs the ``__init__.py`` of each package above it, so it counts as
  importing those packages too -- except the packages that contain the importer (its
  ancestors) and the importer itself: they are already being imported when the importer runs,
  so ``mappers.x`` writing ``from mappers.y import f`` depends on ``mappers.y``, not on
  ``mappers/__init__.py``. A package handing on its sub-modules' names (``__init__.py`` doing
  ``from .y import f``) is therefore no cycle with them, as long as they do not import the
  package back.
* Naming the package itself is importing it, ancestor or not: ``from mappers import build_map``
  inside ``mappers.x`` reads a name ``mappers/__init__.py`` defines, an edge ``mappers.x ->
  mappers`` (and a cycle if ``__init__.py`` imports ``mappers.x``).

A cycle is reported per strongly connected group of modules, as the shortest cycle through each
member (``a -> b -> c -> a``), each followed by the file:line of its imports.
"""

from __future__ import annotations

import ast
from collections import deque
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("mappers", "lfmdr_gym")
FORBIDDEN_IN_MAPPERS = ("gymnasium", "gym", "pygame", "lfmdr_gym")
MAX_LINES = 600
FAMILIES = ("smacof", "paper", "calibrated", "masked", "viewpoints", "fused", "online",
            "spatial")
"""The method families of ``mappers``: each imports ``mappers.core``, the layer below it, and
another family only through the names that family's ``__init__`` declares."""


# ------------------------------------------------------------------ the import graph
def modules_of(root: Path, package: str) -> dict[str, Path]:
    """Module name -> file, for every ``.py`` file under ``root/package``."""
    found = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


def _literal_import_call(node: ast.AST) -> str | None:
    """The module of ``importlib.import_module("m")`` / ``import_module("m")`` /
    ``__import__("m")`` with a literal name, else None."""
    if not isinstance(node, ast.Call) or not node.args:
        return None
    func = node.func
    name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
    arg = node.args[0]
    if name in ("import_module", "__import__") and isinstance(arg, ast.Constant) \
            and isinstance(arg.value, str) and not arg.value.startswith("."):
        return arg.value
    return None


def imports_in(path: Path, module: str) -> list[tuple[str, list[str] | None, int]]:
    """Every import in the file, anywhere in it: ``(absolute module, from-names or None, line)``.

    ``import a.b`` gives ``("a.b", None, line)``; ``from .x import y, z`` in ``p.q`` gives
    ``("p.x", ["y", "z"], line)``.
    """
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = module if is_package else module.rpartition(".")[0]
                parts = package.split(".")
                if node.level - 1 >= len(parts):
                    raise ValueError(f"{path}:{node.lineno}: relative import beyond the top")
                base = ".".join(parts[:len(parts) - node.level + 1])
                base = f"{base}.{node.module}" if node.module else base
            else:
                base = node.module or ""
            found.append((base, [alias.name for alias in node.names], node.lineno))
        elif (name := _literal_import_call(node)) is not None:
            found.append((name, None, node.lineno))
    return sorted(found, key=lambda item: item[2])


def _named(base: str, names: list[str] | None, modules: dict[str, Path]) -> set[str]:
    """The modules an import names: ``from a.b import c`` names ``a.b.c`` if that is a module
    of the tree, else ``a.b``."""
    if names is None:
        return {base}
    return {f"{base}.{n}" if f"{base}.{n}" in modules else base for n in names}


def _parents(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def import_graph(root: Path, package: str) -> dict[str, dict[str, list[int]]]:
    """importer -> {imported module of the same package: [lines]} (the rule of the module
    docstring)."""
    modules = modules_of(root, package)
    graph: dict[str, dict[str, list[int]]] = {m: {} for m in modules}
    for module, path in modules.items():
        own = {module, *_parents(module)}  # the importer and the packages that contain it
        for base, names, line in imports_in(path, module):
            for named in _named(base, names, modules):
                # the module named (unless it is the importer itself), and the packages above it
                # that are not already being imported with the importer
                targets = {named} - {module} | set(_parents(named)) - own
                for target in targets & modules.keys():
                    graph[module].setdefault(target, []).append(line)
    return graph


# ------------------------------------------------------------------ cycles
def strongly_connected(graph: dict[str, dict[str, list[int]]]) -> list[list[str]]:
    """The groups of two or more modules that import one another (in a cycle), and the modules
    that import themselves; each group sorted, the groups sorted (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1 or v in graph[v]:
                groups.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(groups)


def shortest_cycle(graph: dict[str, dict[str, list[int]]], start: str,
                   within: set[str]) -> list[str]:
    """The shortest cycle ``[start, ..., start]`` through ``start`` inside ``within``."""
    came_from: dict[str, str] = {}
    queue = deque([start])
    while queue:
        v = queue.popleft()
        for w in sorted(graph[v]):
            if w not in within:
                continue
            if w == start:
                path = [v]
                while path[-1] != start:
                    path.append(came_from[path[-1]])
                return [start, *reversed(path[:-1]), start] if v != start else [start, start]
            if w not in came_from:
                came_from[w] = v
                queue.append(w)
    raise AssertionError(f"{start} is in no cycle")


def cycles(graph: dict[str, dict[str, list[int]]]) -> list[tuple[list[str], list[list[str]]]]:
    """Per strongly connected group, (its modules, the shortest cycle through each of them,
    each once, written from its smallest module)."""
    found = []
    for group in strongly_connected(graph):
        seen, loops = set(), []
        for start in group:
            loop = shortest_cycle(graph, start, set(group))[:-1]
            first = loop.index(min(loop))
            loop = loop[first:] + loop[:first]
            if tuple(loop) not in seen:
                seen.add(tuple(loop))
                loops.append(loop + loop[:1])
        found.append((group, sorted(loops, key=lambda c: (len(c), c))))
    return found


def cycle_report(root: Path, package: str) -> str:
    """The import cycles among the modules of ``package``, as text ('' when there are none)."""
    graph = import_graph(root, package)
    modules = modules_of(root, package)
    found = cycles(graph)
    if not found:
        return ""
    lines = [f"import cycles among the modules of {package} ({len(found)} group(s)):"]
    for group, loops in found:
        lines.append(f"  {len(group)} modules in a cycle: {', '.join(group)}")
        for loop in loops:
            lines.append("    " + " -> ".join(loop))
            where = [f"{modules[a].relative_to(root).as_posix()}:{graph[a][b][0]}"
                     for a, b in zip(loop, loop[1:], strict=False)]
            lines.append("        (" + ", ".join(where) + ")")
    return "\n".join(lines)


def forbidden_imports(root: Path, package: str, forbidden: tuple[str, ...]) -> list[str]:
    """``file:line imports module`` for each import in ``package`` of a package of
    ``forbidden`` (anywhere in the file)."""
    found = []
    for module, path in modules_of(root, package).items():
        for base, names, line in imports_in(path, module):
            for name in sorted(_named(base, names, {})):
                if name.split(".")[0] in forbidden:
                    found.append(f"{path.relative_to(root).as_posix()}:{line} imports {name}")
    return found


# ------------------------------------------------------------------ the project's tree
def test_mappers_never_imports_the_world():
    found = forbidden_imports(ROOT, "mappers", FORBIDDEN_IN_MAPPERS)
    assert not found, ("mappers must not import " + ", ".join(FORBIDDEN_IN_MAPPERS) + ":\n  "
                       + "\n  ".join(found))


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycles(package):
    report = cycle_report(ROOT, package)
    assert not report, "\n" + report


def test_no_module_over_max_lines():
    long = []
    for package in PACKAGES:
        for path in modules_of(ROOT, package).values():
            n = len(path.read_text(encoding="utf-8").splitlines())
            if n > MAX_LINES:
                long.append(f"{path.relative_to(ROOT).as_posix()}: {n} lines")
    assert not long, f"modules over {MAX_LINES} lines (split them):\n  " + "\n  ".join(long)


def family_breaches(root: Path) -> list[str]:
    """``file:line imports module`` for each import that crosses ``mappers``' rooms the wrong
    way: ``mappers.core`` importing anything of ``mappers`` but ``core`` (it is the bottom),
    :mod:`mappers.catalog` or :mod:`mappers.defaults` importing a family (the catalog names
    methods by entry points and imports none), and a family importing another family's
    sub-module instead of the names its package declares."""
    found = []
    modules = modules_of(root, "mappers")  # once: walking the tree per import took most of the time
    for module, path in modules.items():
        parts = module.split(".")
        own = parts[1] if len(parts) > 1 else None
        for base, names, line in imports_in(path, module):
            for name in sorted(_named(base, names, modules)):
                target = name.split(".")
                if target[0] != "mappers" or len(target) < 2:
                    continue
                where = f"{path.relative_to(root).as_posix()}:{line} imports {name}"
                if own == "core" and target[1] != "core":
                    found.append(where + " (core is the bottom layer)")
                elif own in ("catalog", "defaults") and target[1] in FAMILIES:
                    found.append(where + " (the catalog and the defaults import no method)")
                elif own in FAMILIES and target[1] in FAMILIES and target[1] != own \
                        and len(target) > 2:
                    found.append(where + f" (import it from mappers.{target[1]})")
    return found


def test_method_families_keep_to_their_rooms():
    found = family_breaches(ROOT)
    assert not found, "imports across the families of mappers:\n  " + "\n  ".join(found)


# ------------------------------------------------------------------ the checker itself
def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_cycle_finder_on_a_synthetic_tree(tmp_path):
    _write(tmp_path, {
        # the package hands on its sub-modules' names: no cycle with them
        "pkg/__init__.py": "from .a import f\nfrom . import b\nfrom pkg.sub import y\n",
        "pkg/a.py": "from pkg.b import g\n\ndef f():\n    return g()\n",
        # an import inside a function counts: b -> c
        "pkg/b.py": "def g():\n    from pkg import c\n    return c\n",
        "pkg/c.py": "import os\nfrom .a import f\n",  # c -> a: a -> b -> c -> a
        # a sub-package hands on names too; its module importing a sibling package is no cycle
        "pkg/sub/__init__.py": "from .x import y\n",
        "pkg/sub/x.py": "from ..leaf import z\ny = z\n",
        "pkg/leaf.py": "z = 1\n",
        # a module outside `sub` importing from it runs sub/__init__.py: other -> sub, and
        # sub/__init__.py importing `other` back closes a cycle
        "pkg/other.py": "from pkg.sub.x import y\n",
        # reading a name of the package's own __init__ is importing it: q -> q.m -> q
        "q/__init__.py": "VERSION = 1\nfrom .m import h\n",
        "q/m.py": "def h():\n    import importlib\n    return importlib.import_module('q').VERSION\n",
    })
    graph = import_graph(tmp_path, "pkg")
    assert graph["pkg.b"] == {"pkg.c": [2]}  # inside a function, `from pkg import c` -> pkg.c
    assert graph["pkg.a"] == {"pkg.b": [1]}  # not pkg/__init__.py: pkg contains pkg.a
    assert graph["pkg.sub.x"] == {"pkg.leaf": [1]}  # relative import two levels up
    assert graph["pkg.other"] == {"pkg.sub": [1], "pkg.sub.x": [1]}  # sub/__init__.py runs
    assert graph["pkg"] == {"pkg.a": [1], "pkg.b": [2], "pkg.sub": [3]}  # y: a name, not a module
    assert cycles(graph) == [(["pkg.a", "pkg.b", "pkg.c"],
                              [["pkg.a", "pkg.b", "pkg.c", "pkg.a"]])]
    report = cycle_report(tmp_path, "pkg")
    assert "pkg.a -> pkg.b -> pkg.c -> pkg.a" in report
    assert "(pkg/a.py:1, pkg/b.py:2, pkg/c.py:2)" in report

    (tmp_path / "pkg/sub/__init__.py").write_text("from .x import y\nfrom pkg import other\n")
    found = dict((tuple(g), loops) for g, loops in cycles(import_graph(tmp_path, "pkg")))
    assert found[("pkg.other", "pkg.sub")] == [["pkg.other", "pkg.sub", "pkg.other"]]

    assert cycles(import_graph(tmp_path, "q")) == [(["q", "q.m"], [["q", "q.m", "q"]])]


def test_forbidden_imports_are_found_anywhere(tmp_path):
    _write(tmp_path, {
        "lib/__init__.py": "",
        "lib/ok.py": "import numpy as np\nimport gymnasium_robotics_like\n",
        "lib/late.py": "class A:\n    def run(self):\n        from lfmdr_gym.env import X\n",
        "lib/top.py": "import gym.spaces\n",
        "lib/dyn.py": "import importlib\nm = importlib.import_module('pygame')\n",
    })
    assert forbidden_imports(tmp_path, "lib", FORBIDDEN_IN_MAPPERS) == [
        "lib/dyn.py:2 imports pygame",
        "lib/late.py:3 imports lfmdr_gym.env",
        "lib/top.py:1 imports gym.spaces",
    ]
