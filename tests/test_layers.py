"""The package's layers (docs/architecture.md): a module imports only from layers below its own
(or from its own package), physics modules never read the scene, and there is no import cycle.

Every ``import`` statement counts, also those inside functions: a function-level import that
breaks the layering is a defect just as a top-level one (it only hides the dependency).
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "drumheat"

#: the layers, lowest first; a module belongs to the first entry that is a prefix of its name
LAYERS = [
    ("drumheat._version", "drumheat.materials", "drumheat.environment", "drumheat.devices"),
    ("drumheat.models", "drumheat.geometry"),
    ("drumheat.scene",),
    ("drumheat.thermal", "drumheat.mechanics"),
    ("drumheat.assemble",),
    ("drumheat.motion",),
    ("drumheat.results",),
    ("drumheat.runner",),
    ("drumheat.analysis", "drumheat.experiments"),
    ("drumheat.cli", "drumheat._aliases", "drumheat.__main__", "drumheat"),
]

#: packages that hold physics: they work on arrays and explicit arguments, never on a scene
PHYSICS = ("drumheat.models", "drumheat.geometry", "drumheat.thermal", "drumheat.mechanics")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def unit(name: str) -> tuple[int, str]:
    """(layer index, package) of a module: the first layer entry that is a prefix of it."""
    for k, entries in enumerate(LAYERS):
        for e in entries:
            if name == e or name.startswith(e + "."):
                return k, ("top" if k == len(LAYERS) - 1 else e)  # the top layer is one unit
    raise AssertionError(f"module {name} is in no layer; add it to LAYERS")


def imports(name: str) -> set[str]:
    """The drumheat modules ``name`` imports (at any depth in the file)."""
    path = MODULES[name]
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]
                                + ([base] if base else []))
            for a in node.names:
                full = f"{base}.{a.name}"
                out.add(full if full in MODULES else base)
    return {m for m in out if m == "drumheat" or m.startswith("drumheat.")}


EDGES = {name: imports(name) for name in MODULES}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_go_down_the_layers(name):
    layer, package = unit(name)
    for target in sorted(EDGES[name]):
        if target not in MODULES:
            continue
        t_layer, t_package = unit(target)
        if t_package == package:
            continue  # inside one package
        assert t_layer < layer, (f"{name} (layer {layer}, {package}) imports {target} (layer "
                                 f"{t_layer}, {t_package}): only lower layers may be imported")


@pytest.mark.parametrize("name", sorted(m for m in MODULES if m.startswith(PHYSICS)))
def test_physics_never_reads_the_scene(name):
    assert not any(t == "drumheat.scene" or t.startswith("drumheat.scene.")
                   for t in EDGES[name]), f"{name} imports the scene"


def test_no_import_cycles():
    graph = {m: {t for t in EDGES[m] if t in MODULES and t != m} for m in MODULES}
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []
    counter = [0]

    def strong(v):  # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            strong(v)
    assert cycles == [], f"import cycles: {cycles}"


def test_every_module_is_in_a_layer():
    for name in MODULES:
        unit(name)


def test_an_old_import_path_warns_and_gives_the_module_at_its_new_place():
    """drumheat._aliases: a module moved in the layered layout is still importable by its old
    path for one release, with a DeprecationWarning naming the new one."""
    import importlib
    import sys

    import drumheat.thermal.solvers as new

    sys.modules.pop("drumheat.thermal.integrate", None)
    with pytest.warns(DeprecationWarning, match="moved to 'drumheat.thermal.solvers'"):
        old = importlib.import_module("drumheat.thermal.integrate")
    assert old is new
