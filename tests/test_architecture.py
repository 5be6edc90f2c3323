"""The design contract of DESIGN.md section 1, executable.

Every module of ``src/robopercept`` is parsed with :mod:`ast` (the package is not
imported, except by the import-time test, which runs in a subprocess) and its imports,
absolute and relative, at module level and inside functions, are resolved to module
names. Three checkers, each a plain function ``(source, module) -> list[str]`` of
violations, enforce:

* **floors** -- a module imports only from its own floor or below; ``torch`` is
  imported only in ``nn``, and ``nn`` only by ``cli`` and ``pipelines``, lazily
  (inside a function);
* **private names** -- no module imports another module's private name (``_x``, not a
  dunder), reads ``module._x`` through an imported module, or imports a private module
  (``calibration/_lattice.py``) from outside that module's own package.
  ``robopercept._checks`` is shared by every floor by design;
* **cycles** -- no two topic packages import each other, directly or round a loop;
* **inside nn** -- the same floors one level down (:data:`NN_FLOORS`): torch-free
  ground files, then the shared floors (core, ops, coco, data, train), then the task
  wings (a wing imports no other wing but those of :data:`NN_WING_USES`), then
  predict; the modules of :data:`NN_TORCH_FREE` load no torch; no ``robopercept``
  import inside a function of nn, except a torch-free module reaching torch.

The checkers are tested on deliberately bad and good sources first, so a green run
on the real tree means something.

Floors of the top-level modules (a decision DESIGN.md leaves open): the package
``robopercept/__init__.py`` is floor 1 -- it must stay import-cheap and so may import
nothing above ``errors``/``_checks``; a ``robopercept/__main__.py``, if one is added,
is an entry point like the command line and sits on floor 6 with ``cli``.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path

import pytest

PKG = "robopercept"
SRC = Path(__file__).resolve().parents[1] / "src" / PKG

#: floor of each top-level part of the package (the second component of a module name;
#: ``__init__`` stands for the package ``robopercept`` itself)
FLOORS: dict[str, int] = {
    "__init__": 1,
    "errors": 1,
    "_checks": 1,
    "progress": 1,
    "jit": 1,
    "fileio": 1,
    "imaging": 2,
    "geometry": 2,
    "estimation": 2,
    "features": 3,
    "motion": 3,
    "learning": 3,
    "depth": 3,
    "calibration": 3,
    "pointcloud": 3,
    "tracking": 4,
    "viz": 4,
    "sources": 5,
    "pipelines": 5,
    "nn": 5,
    "cli": 6,
    "__main__": 6,
}
#: private modules shared with every package by design
SHARED_PRIVATE = {f"{PKG}._checks"}
#: the only top-level parts that may import ``nn`` (and only lazily)
NN_IMPORTERS = {"cli", "pipelines"}
#: third-party packages only ``nn`` may import
NN_ONLY = {"torch", "torchvision"}


# -- discovery -----------------------------------------------------------------------


def module_name(path: Path, root: Path = SRC) -> str:
    """``src/robopercept/imaging/filters.py`` -> ``robopercept.imaging.filters``."""
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def discover(root: Path = SRC) -> dict[str, Path]:
    """Every module of the package: name -> file."""
    return {module_name(p, root): p for p in sorted(root.rglob("*.py"))}


MODULES = discover()
PACKAGES = {name for name, path in MODULES.items() if path.name == "__init__.py"}


def top_part(module: str) -> str:
    """``robopercept.imaging.filters`` -> ``imaging``; ``robopercept`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_module_owner(module: str) -> str | None:
    """The package inside which a private module may be imported, or None if public.

    ``robopercept.calibration._lattice`` -> ``robopercept.calibration``. A module is
    private when any of its components below ``robopercept`` is private.
    """
    if module in SHARED_PRIVATE:
        return None
    parts = module.split(".")
    for i in range(1, len(parts)):
        if is_private(parts[i]):
            return ".".join(parts[:i])
    return None


# -- import resolution ---------------------------------------------------------------


class Import:
    """One imported thing: the module it lives in, the name taken from it (if any)."""

    def __init__(
        self,
        module: str,
        name: str | None,
        node: ast.AST,
        lazy: bool,
        bound: str | None = None,
        binds_to: str | None = None,
    ) -> None:
        self.module = module  # the module imported (a submodule if ``name`` is one)
        self.name = name  # the attribute taken from ``module`` (None: the module itself)
        self.lineno = getattr(node, "lineno", 0)
        self.lazy = lazy  # inside a function or under ``if TYPE_CHECKING``
        self.bound = bound  # the local name bound to a module object, if any
        self.binds_to = binds_to  # ... and the module that name refers to

    def __repr__(self) -> str:
        return f"Import({self.module!r}, {self.name!r}, line {self.lineno})"


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _walk(node: ast.AST, lazy: bool = False) -> Iterator[tuple[ast.AST, bool]]:
    """Every node with a flag: inside a function body (or a TYPE_CHECKING block)."""
    for child in ast.iter_child_nodes(node):
        inner = lazy or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
        if isinstance(child, ast.If) and _is_type_checking(child.test):
            yield child, lazy
            for n in child.body:
                yield n, True
                yield from _walk(n, True)
            for n in child.orelse:
                yield n, lazy
                yield from _walk(n, lazy)
            continue
        yield child, lazy
        yield from _walk(child, inner)


def resolve_imports(
    tree: ast.Module,
    module: str,
    *,
    is_package: bool = False,
    modules: Iterable[str] = MODULES,
) -> list[Import]:
    """Every import of ``tree`` (module ``module``), resolved to absolute names.

    ``from a.b import c`` yields ``Import("a.b.c", None)`` when ``a.b.c`` is a module
    and ``Import("a.b", "c")`` otherwise; relative imports are resolved against the
    module's package (the module itself when ``is_package``).
    """
    known = set(modules)
    package = module if is_package else module.rpartition(".")[0]
    out: list[Import] = []
    for node, lazy in _walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                bound = alias.asname or alias.name.split(".")[0]
                target = alias.name if alias.asname else alias.name.split(".")[0]
                out.append(Import(alias.name, None, node, lazy, bound, target))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                if node.level > 1:
                    base = base[: len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                if sub in known:
                    bound = alias.asname or alias.name
                    out.append(Import(sub, None, node, lazy, bound, sub))
                else:
                    out.append(Import(source, alias.name, node, lazy))
    return out


def _parse(source: str, module: str) -> ast.Module:
    return ast.parse(source, filename=module)


def _ours(name: str) -> bool:
    return name == PKG or name.startswith(PKG + ".")


# -- the three checkers --------------------------------------------------------------


def floor_violations(
    source: str, module: str, *, is_package: bool = False, modules: Iterable[str] = MODULES
) -> list[str]:
    """Imports that run up a floor, torch outside ``nn``, ``nn`` imported eagerly or
    from outside ``cli``/``pipelines``."""
    me = top_part(module)
    if me not in FLOORS:
        return [f"{module}: top-level part {me!r} has no floor; add it to FLOORS"]
    out = []
    tree = _parse(source, module)
    for imp in resolve_imports(tree, module, is_package=is_package, modules=modules):
        where = f"{module}:{imp.lineno}"
        root = imp.module.split(".")[0]
        if root in NN_ONLY and me != "nn":
            out.append(f"{where} imports {imp.module} (only robopercept.nn imports torch)")
        if not _ours(imp.module):
            continue
        target = imp.module
        if target == PKG and imp.name is not None and f"{PKG}.{imp.name}" in FLOORS:
            target = f"{PKG}.{imp.name}"
        other = top_part(target)
        if other not in FLOORS:
            out.append(f"{where} imports {target}, which has no floor")
            continue
        if FLOORS[other] > FLOORS[me]:
            out.append(f"{where} imports {target} (floor {FLOORS[other]}) from floor {FLOORS[me]}")
        if other == "nn" and me != "nn":
            if me not in NN_IMPORTERS:
                out.append(f"{where} imports {target}; only cli and pipelines may import nn")
            elif not imp.lazy:
                out.append(f"{where} imports {target} at module level; import nn lazily")
    return out


def private_violations(
    source: str, module: str, *, is_package: bool = False, modules: Iterable[str] = MODULES
) -> list[str]:
    """Private names taken from other modules, ``module._x`` reads through an imported
    module, private modules imported from outside their own package."""
    known = set(modules)
    out = []
    tree = _parse(source, module)
    imports = resolve_imports(tree, module, is_package=is_package, modules=known)
    aliases: dict[str, str] = {}  # local name -> module it is bound to
    for imp in imports:
        where = f"{module}:{imp.lineno}"
        if not _ours(imp.module):
            continue
        if imp.name is not None and is_private(imp.name) and imp.module != module:
            out.append(f"{where} imports private name {imp.name} from {imp.module}")
        owner = private_module_owner(imp.module)
        if owner is not None and not (module == owner or module.startswith(owner + ".")):
            out.append(f"{where} imports private module {imp.module} from outside {owner}")
        if imp.bound is not None and imp.binds_to is not None:
            aliases[imp.bound] = imp.binds_to
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and is_private(node.attr)):
            continue
        chain: list[str] = []
        value: ast.expr = node.value
        while isinstance(value, ast.Attribute):
            chain.append(value.attr)
            value = value.value
        if not isinstance(value, ast.Name) or value.id not in aliases:
            continue
        owner_module = ".".join([aliases[value.id], *reversed(chain)])
        if _ours(owner_module) and owner_module != module and owner_module in known:
            out.append(f"{module}:{node.lineno} reads private name {node.attr} of {owner_module}")
    return out


def package_graph(
    sources: dict[str, str], packages: set[str] = PACKAGES, *, modules: bool = False
) -> dict[str, set[str]]:
    """Top-level part -> the other top-level parts it imports (lazy imports included);
    with ``modules``, module -> the other modules it imports."""
    graph: dict[str, set[str]] = {}
    known = set(sources)
    for module, source in sources.items():
        me = module if modules else top_part(module)
        graph.setdefault(me, set())
        tree = _parse(source, module)
        for imp in resolve_imports(tree, module, is_package=module in packages, modules=known):
            if _ours(imp.module):
                other = imp.module if modules else top_part(imp.module)
                if imp.module == PKG and imp.name and f"{PKG}.{imp.name}" in known:
                    other = f"{PKG}.{imp.name}" if modules else imp.name
                if other != me:
                    graph[me].add(other)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one member (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


# -- the checkers on deliberately bad and good sources -------------------------------


class TestCheckers:
    def test_floor_upward_import_is_caught(self) -> None:
        bad = "from robopercept.cli.main import main\n"
        v = floor_violations(bad, "robopercept.imaging.x")
        assert len(v) == 1 and "floor 6" in v[0] and "floor 2" in v[0]

    def test_floor_inside_function_is_caught(self) -> None:
        bad = "def f():\n    import robopercept.tracking.kalman as k\n    return k\n"
        assert len(floor_violations(bad, "robopercept.features.x")) == 1

    def test_floor_relative_upward_import_is_caught(self) -> None:
        bad = "from ..viz import draw_keypoints\n"
        v = floor_violations(bad, "robopercept.features.x")
        assert len(v) == 1 and "robopercept.viz" in v[0]
        bad2 = "from ...cli import main\n"  # from a subpackage two levels down
        assert len(floor_violations(bad2, "robopercept.imaging.sub.x")) == 1

    def test_floor_from_package_import_submodule(self) -> None:
        bad = "from robopercept import viz\n"
        assert len(floor_violations(bad, "robopercept.geometry.x")) == 1
        assert floor_violations("from robopercept import errors\n", "robopercept.geometry.x") == []

    def test_floor_good_imports_pass(self) -> None:
        good = (
            "import numpy as np\n"
            "from robopercept.errors import InputError\n"
            "from robopercept._checks import check_image\n"
            "from robopercept.imaging import gaussian_blur\n"
            "from .harris import harris_corners\n"
            "from . import hog\n"
            "import robopercept.geometry.camera as camera\n"
        )
        assert floor_violations(good, "robopercept.features.x") == []

    def test_torch_and_nn_rules(self) -> None:
        assert len(floor_violations("import torch\n", "robopercept.learning.x")) == 1
        assert floor_violations("import torch.nn as tnn\n", "robopercept.nn.x") == []
        eager = "from robopercept.nn import train\n"
        assert len(floor_violations(eager, "robopercept.cli.x")) == 1
        lazy = "def run():\n    from robopercept.nn import train\n    return train\n"
        assert floor_violations(lazy, "robopercept.cli.x") == []
        assert floor_violations(lazy, "robopercept.pipelines.x") == []
        assert len(floor_violations(lazy, "robopercept.sources.x")) == 1

    def test_unknown_top_level_part(self) -> None:
        assert len(floor_violations("", "robopercept.newtopic.x")) == 1

    def test_private_name_is_caught(self) -> None:
        bad = "from robopercept.geometry.camera import _distort\n"
        v = private_violations(bad, "robopercept.depth.rgbd")
        assert len(v) == 1 and "_distort" in v[0]

    def test_private_name_multiline_and_inside_function(self) -> None:
        bad = (
            "def f():\n"
            "    from robopercept.learning.tree import (\n"
            "        DecisionTreeClassifier,\n"
            "        _grow,\n"
            "        _Tree as T,\n"
            "    )\n"
        )
        v = private_violations(bad, "robopercept.learning.forest")
        assert len(v) == 2 and {"_grow", "_Tree"} == {s.split()[-3] for s in v}

    def test_private_name_relative_import_is_caught(self) -> None:
        bad = "from .background import _check_threshold\n"
        v = private_violations(bad, "robopercept.motion.differencing")
        assert len(v) == 1 and "robopercept.motion.background" in v[0]
        bad2 = "from ..imaging.filters import _box\n"
        assert len(private_violations(bad2, "robopercept.features.x")) == 1

    def test_private_attribute_access_is_caught(self) -> None:
        bad = "from robopercept.viz import draw\n\ndef f(x):\n    return draw._color(x)\n"
        v = private_violations(bad, "robopercept.viz.flow")
        assert len(v) == 1 and "robopercept.viz.draw" in v[0]
        bad2 = "import robopercept.viz.draw as d\ny = d._canvas\n"
        assert len(private_violations(bad2, "robopercept.viz.features")) == 1
        bad3 = "import robopercept.viz.draw\ny = robopercept.viz.draw._canvas\n"
        assert len(private_violations(bad3, "robopercept.viz.features")) == 1

    def test_private_module_from_another_package_is_caught(self) -> None:
        bad = "from robopercept.calibration._lattice import grow\n"
        assert len(private_violations(bad, "robopercept.features.x")) == 1
        bad2 = "from robopercept.features import _atan\n"
        assert len(private_violations(bad2, "robopercept.imaging.x")) == 1

    def test_private_good_imports_pass(self) -> None:
        good = (
            "import numpy as np\n"
            "from ._lattice import grow\n"
            "from . import _lattice\n"
            "from robopercept._checks import check_image\n"
            "from robopercept.geometry.camera import distort\n"
            "from robopercept.geometry import camera\n"
            "y = camera.distort\n"
            "z = np._NoValue\n"  # not ours
            "class A:\n    def f(self):\n        return self._x\n"
        )
        assert private_violations(good, "robopercept.calibration.chessboard") == []
        pkg = "from ._lattice import grow\n"
        assert private_violations(pkg, "robopercept.calibration", is_package=True) == []

    def test_cycle_detection(self) -> None:
        sources = {
            "robopercept.features.a": "from robopercept.motion.b import f\n",
            "robopercept.motion.b": "def g():\n    from robopercept.features.a import h\n",
            "robopercept.imaging.c": "from robopercept.errors import InputError\n",
            "robopercept.errors": "",
        }
        graph = package_graph(sources, packages=set())
        assert cycles(graph) == [["features", "motion"]]
        del sources["robopercept.motion.b"]
        assert cycles(package_graph(sources, packages=set())) == []


# -- the real tree ---------------------------------------------------------------------


def _real_violations(check) -> list[str]:
    found = []
    for name, path in MODULES.items():
        found += check(path.read_text(encoding="utf-8"), name, is_package=name in PACKAGES)
    return found


def test_modules_were_found() -> None:
    assert f"{PKG}.imaging.filters" in MODULES and f"{PKG}.cli" in PACKAGES


def test_floors() -> None:
    found = _real_violations(floor_violations)
    assert not found, "imports that run up a floor (DESIGN.md section 1):\n" + "\n".join(found)


def test_no_private_imports() -> None:
    found = _real_violations(private_violations)
    assert not found, "private names used across modules:\n" + "\n".join(found)


def test_no_package_cycles() -> None:
    sources = {name: path.read_text(encoding="utf-8") for name, path in MODULES.items()}
    found = cycles(package_graph(sources))
    assert not found, f"packages that import each other: {found}"


def test_no_module_cycles() -> None:
    sources = {name: path.read_text(encoding="utf-8") for name, path in MODULES.items()}
    found = cycles(package_graph(sources, modules=True))
    assert not found, f"modules that import each other: {found}"


def _run(code: str) -> str:
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    return out.stdout.strip()


def test_import_robopercept_is_cheap() -> None:
    """``import robopercept`` loads no torch, no numba, opens no file but its own code."""
    code = (
        "import sys\n"
        "opened = []\n"
        "def hook(event, args):\n"
        "    if event == 'open' and isinstance(args[0], str):\n"
        "        opened.append(args[0])\n"
        "sys.addaudithook(hook)\n"
        "import robopercept\n"
        "code = ('.py', '.pyc', '.so', '.pth')\n"
        "data = [p for p in opened if not p.endswith(code)]\n"
        "print('torch' in sys.modules, 'numba' in sys.modules, data)\n"
    )
    assert _run(code) == "False False []"


@pytest.mark.skipif(sys.platform == "win32", reason="imports every module; POSIX CI only")
def test_no_module_imports_torch_or_compiles_at_import() -> None:
    """Importing every module outside ``nn`` loads no torch and compiles no kernel."""
    names = [n for n in MODULES if top_part(n) != "nn" and not n.endswith("__main__")]
    code = (
        "import importlib, sys\n"
        f"names = {names!r}\n"
        "for n in names:\n"
        "    importlib.import_module(n)\n"
        "from numba.core.registry import CPUDispatcher\n"
        "compiled = sorted(\n"
        "    f'{m}.{k}' for m in names for k, v in vars(sys.modules[m]).items()\n"
        "    if isinstance(v, CPUDispatcher) and v.signatures\n"
        ")\n"
        "print('torch' in sys.modules, compiled)\n"
    )
    assert _run(code) == "False []"


# -- inside nn: the floors of its subpackages (DESIGN.md section 1, issue 45) ----------

#: floor of each part of ``robopercept.nn`` (the third component of a module name;
#: ``__init__`` stands for the package ``robopercept.nn`` itself): torch-free ground
#: files; the shared floors; the task wings; the predictor on top
NN_FLOORS: dict[str, int] = {
    "__init__": 1,
    "_guards": 1,
    "functional": 1,
    "skeleton": 1,
    "shipped": 1,
    "core": 2,
    "ops": 2,
    "coco": 2,
    "data": 2,
    "train": 2,
    "classification": 3,
    "detection": 3,
    "segmentation": 3,
    "pose": 3,
    "cloud": 3,
    "predict": 4,
    "predict_class": 4,
}
#: the only wing-to-wing arrows: segmentation and pose build on detection
NN_WING_USES: dict[str, set[str]] = {"segmentation": {"detection"}, "pose": {"detection"}}
#: the modules of nn that load no torch when imported (checked by importing each in a
#: fresh interpreter); they may reach torch only inside a function
NN_TORCH_FREE: tuple[str, ...] = (
    f"{PKG}.nn",
    *(
        f"{PKG}.nn.{m}"
        for m in (
            "_guards",
            "functional",
            "skeleton",
            "shipped",
            "coco",
            "coco._fields",
            "coco.rle",
            "coco.dataset",
            "coco.results",
            "coco.evaluate",
            "coco.voc",
            "coco.folders",
            "data.fonts",
            "segmentation.metrics",
            "pose.metrics",
            "pose.pictorial",
            "pose.io",
        )
    ),
)


def nn_part(module: str) -> str:
    """``robopercept.nn.detection.fcos`` -> ``detection``; ``robopercept.nn`` -> ``__init__``."""
    parts = module.split(".")
    return parts[2] if len(parts) > 2 else "__init__"


def _nn_imports(
    source: str, module: str, is_package: bool, modules: Iterable[str]
) -> Iterator[tuple[Import, str]]:
    """Each import of ``module`` with the module it reaches
    (``from robopercept.nn import ops`` -> ``robopercept.nn.ops``)."""
    known = set(modules)
    tree = _parse(source, module)
    for imp in resolve_imports(tree, module, is_package=is_package, modules=known):
        sub = f"{imp.module}.{imp.name}"
        yield imp, sub if imp.name is not None and sub in known else imp.module


def nn_floor_violations(
    source: str,
    module: str,
    *,
    is_package: bool = False,
    modules: Iterable[str] = MODULES,
    torch_free: Iterable[str] = NN_TORCH_FREE,
) -> list[str]:
    """Inside ``nn``: imports that run up an nn floor, a wing importing a wing it may
    not, torch imported at module level by a module on the torch-free list."""
    if top_part(module) != "nn":
        return []
    me = nn_part(module)
    if me not in NN_FLOORS:
        return [f"{module}: part {me!r} of nn has no floor; add it to NN_FLOORS"]
    known, free = set(modules), set(torch_free)
    out = []
    for imp, target in _nn_imports(source, module, is_package, known):
        where = f"{module}:{imp.lineno}"
        if imp.module.split(".")[0] in NN_ONLY and module in free and not imp.lazy:
            out.append(f"{where} imports {imp.module} at module level in a torch-free module")
        if not _ours(target) or top_part(target) != "nn":
            continue
        other = nn_part(target)
        if other not in NN_FLOORS:
            out.append(f"{where} imports {target}, a part of nn with no floor")
        elif NN_FLOORS[other] > NN_FLOORS[me]:
            out.append(
                f"{where} imports {target} (nn floor {NN_FLOORS[other]}) from nn floor "
                f"{NN_FLOORS[me]}"
            )
        elif NN_FLOORS[me] == NN_FLOORS[other] == 3 and other != me:
            if other not in NN_WING_USES.get(me, set()):
                out.append(f"{where}: the {me} wing imports the {other} wing")
        elif target in known and module in free and not imp.lazy and target not in free:
            out.append(f"{where}: torch-free {module} imports {target} at module level")
    return out


def nn_local_import_violations(
    source: str,
    module: str,
    *,
    is_package: bool = False,
    modules: Iterable[str] = MODULES,
    torch_free: Iterable[str] = NN_TORCH_FREE,
) -> list[str]:
    """Inside ``nn``: ``robopercept`` imports inside a function, which hide the module's
    real arrows; the one exception is a torch-free module reaching a torch module."""
    if top_part(module) != "nn":
        return []
    free = set(torch_free)
    out: list[str] = []
    for imp, target in _nn_imports(source, module, is_package, modules):
        if not imp.lazy or not _ours(target):
            continue
        if module in free and top_part(target) == "nn" and target not in free:
            continue  # a torch-free module reaching torch lazily
        line = f"{module}:{imp.lineno} imports {target} inside a function"
        if line not in out:
            out.append(line)
    return out


class TestNnCheckers:
    """The nn checkers on made-up sources, so that a green run on the tree means
    something."""

    MODS = (
        f"{PKG}.nn",
        f"{PKG}.nn.functional",
        f"{PKG}.nn.shipped",
        f"{PKG}.nn.ops",
        f"{PKG}.nn.ops.boxes",
        f"{PKG}.nn.train",
        f"{PKG}.nn.train.loop",
        f"{PKG}.nn.train.fit",
        f"{PKG}.nn.detection",
        f"{PKG}.nn.detection.fcos",
        f"{PKG}.nn.pose.networks",
        f"{PKG}.nn.cloud.pointnet",
        f"{PKG}.nn.predict",
    )
    FREE = (f"{PKG}.nn.functional", f"{PKG}.nn.shipped", f"{PKG}.nn.coco.x")

    def check(self, source: str, module: str) -> list[str]:
        return nn_floor_violations(source, module, modules=self.MODS, torch_free=self.FREE)

    def local(self, source: str, module: str) -> list[str]:
        return nn_local_import_violations(source, module, modules=self.MODS, torch_free=self.FREE)

    def test_upward_import_is_caught(self) -> None:
        bad = "from robopercept.nn.detection.fcos import FCOS\n"
        v = self.check(bad, f"{PKG}.nn.ops.boxes")
        assert len(v) == 1 and "nn floor 3" in v[0] and "from nn floor 2" in v[0]
        bad2 = "from robopercept.nn import predict\n"
        assert len(self.check(bad2, f"{PKG}.nn.train.loop")) == 1
        bad3 = "from ..predict import predict\n"  # relative, from a subpackage
        assert len(self.check(bad3, f"{PKG}.nn.ops.boxes")) == 1

    def test_wing_to_wing(self) -> None:
        assert self.check("from robopercept.nn.detection import fcos\n", f"{PKG}.nn.pose.x") == []
        bad = "from robopercept.nn.pose.networks import HRNet\n"
        v = self.check(bad, f"{PKG}.nn.detection.x")
        assert len(v) == 1 and "detection wing imports the pose wing" in v[0]
        assert len(self.check(bad, f"{PKG}.nn.cloud.x")) == 1

    def test_downward_and_same_floor_pass(self) -> None:
        good = (
            "import torch\n"
            "from robopercept.nn.ops.boxes import box_iou\n"
            "from robopercept.nn.train.fit import fit\n"
            "from robopercept.nn import functional\n"
            "from robopercept.imaging import read_image\n"
            "from .fcos import FCOS\n"
        )
        assert self.check(good, f"{PKG}.nn.detection.x") == []

    def test_torch_free_modules(self) -> None:
        assert len(self.check("import torch\n", f"{PKG}.nn.functional")) == 1
        eager = "from robopercept.nn.train.fit import fit\n"
        v = self.check(eager, f"{PKG}.nn.coco.x")  # same floor, but it loads torch
        assert len(v) == 1 and "torch-free" in v[0]
        assert len(self.check(eager, f"{PKG}.nn.shipped")) == 1  # upward
        lazy = "def f():\n    import torch\n    return torch\n"
        assert self.check(lazy, f"{PKG}.nn.functional") == []

    def test_unknown_part(self) -> None:
        assert len(self.check("", f"{PKG}.nn.newwing.x")) == 1

    def test_local_imports(self) -> None:
        bad = "def f():\n    from robopercept.nn.ops.boxes import nms\n    return nms\n"
        v = self.local(bad, f"{PKG}.nn.detection.fcos")
        assert len(v) == 1 and "inside a function" in v[0]
        viz = "def f():\n    from robopercept.viz import draw_boxes\n"
        assert len(self.local(viz, f"{PKG}.nn.train.loop")) == 1
        reach = "def f():\n    from robopercept.nn.detection.fcos import FCOS\n"
        assert self.local(reach, f"{PKG}.nn.shipped") == []  # torch-free reaching torch
        free = "def f():\n    from robopercept.nn import functional\n"
        assert len(self.local(free, f"{PKG}.nn.shipped")) == 1
        assert self.local("from robopercept.nn.ops import boxes\n", f"{PKG}.nn.x") == []


def test_nn_parts_have_floors() -> None:
    parts = {nn_part(n) for n in MODULES if top_part(n) == "nn"}
    assert parts <= set(NN_FLOORS), parts - set(NN_FLOORS)


def test_nn_floors() -> None:
    found = _real_violations(nn_floor_violations)
    assert not found, "imports that run up nn's floors (DESIGN.md section 1):\n" + "\n".join(found)


def test_nn_no_function_local_imports() -> None:
    found = _real_violations(nn_local_import_violations)
    assert not found, "robopercept imports inside functions of nn:\n" + "\n".join(found)


def test_nn_torch_free_modules_load_no_torch() -> None:
    """Each module on :data:`NN_TORCH_FREE` imports without loading torch."""
    assert set(NN_TORCH_FREE) <= set(MODULES), set(NN_TORCH_FREE) - set(MODULES)
    code = (
        "import importlib, sys\n"
        f"for n in {list(NN_TORCH_FREE)!r}:\n"
        "    importlib.import_module(n)\n"
        "    assert 'torch' not in sys.modules, n\n"
        "print('ok')\n"
    )
    assert _run(code) == "ok"


# ------------------------------------------------------------------ the CLI reaches nn's runs only
#: what a ``cli`` module may import from nn (issue 45): the run modules of the task
#: wings, the predictor and the shipped-model table; everything else is reached through
#: them, so that the CLI parses and prints while the library owns the runs
CLI_NN_ALLOWED: tuple[str, ...] = (
    f"{PKG}.nn.classification.run",
    f"{PKG}.nn.detection.run",
    f"{PKG}.nn.segmentation.run",
    f"{PKG}.nn.pose.run",
    f"{PKG}.nn.cloud.run",
    f"{PKG}.nn.predict",
    f"{PKG}.nn.shipped",
)


def cli_nn_violations(
    source: str,
    module: str,
    *,
    is_package: bool = False,
    modules: Iterable[str] = MODULES,
    allowed: Iterable[str] = CLI_NN_ALLOWED,
) -> list[str]:
    """Inside ``cli``: imports of nn modules other than :data:`CLI_NN_ALLOWED`
    (function-local ones too: the CLI imports torch only when a command runs)."""
    if top_part(module) != "cli":
        return []
    ok = set(allowed)
    out = []
    for imp, target in _nn_imports(source, module, is_package, modules):
        if _ours(target) and top_part(target) == "nn" and target not in ok:
            out.append(
                f"{module}:{imp.lineno} imports {target}; the CLI reaches nn through the run "
                "modules, the predictor and the shipped table only"
            )
    return out


class TestCliNnChecker:
    MODS = (
        f"{PKG}.nn",
        f"{PKG}.nn.train.config",
        f"{PKG}.nn.detection.run",
        f"{PKG}.nn.detection.train",
        f"{PKG}.nn.predict",
        f"{PKG}.cli.nn.detect",
    )

    def check(self, source: str, module: str = f"{PKG}.cli.nn.detect") -> list[str]:
        return cli_nn_violations(source, module, modules=self.MODS)

    def test_a_deep_import_is_caught(self) -> None:
        bad = "def f():\n    from robopercept.nn.train.config import TrainConfig\n"
        v = self.check(bad)
        assert len(v) == 1 and "nn.train.config" in v[0] and ":2 " in v[0]
        assert len(self.check("from robopercept.nn.detection import train\n")) == 1

    def test_runs_predictor_and_shipped_pass(self) -> None:
        good = (
            "def f():\n"
            "    from robopercept.nn.detection.run import TrainConfig, train_run\n"
            "    from robopercept.nn.predict import load_image_predictor\n"
            "    from robopercept.nn.shipped import SHIPPED\n"
            "    from robopercept.imaging import read_image\n"
        )
        assert self.check(good) == []
        assert self.check("from robopercept.nn.train import config\n", f"{PKG}.viz.x") == []


def test_cli_imports_only_nn_runs() -> None:
    found = _real_violations(cli_nn_violations)
    assert not found, "cli modules importing nn beyond its runs:\n" + "\n".join(found)
