"""The packages' import graph has no loop and no module takes another's private names; the
product never imports the simulator.

Walks ``hmocap_ros/**/*.py`` and ``hmocap_sim/**/*.py`` with :mod:`ast`, every import statement
counted (at the top of a file, inside a function, under ``TYPE_CHECKING``), and fails, naming
them, on

- a file cycle: modules that import one another, directly or through others;
- a folder cycle: top-level subpackages of ``hmocap_ros`` (``detection``, ``tracking``, ...; a
  top-level module such as ``rig`` is a node of its own) that import one another;
- a cross-module private import: ``from module import _name`` or ``module._name`` through an
  imported module, where the module is another module of the package;
- ``geometry/`` importing anything else of the package (it is the bottom layer);
- a module of ``hmocap_ros`` importing ``hmocap_sim`` (the ``hmocap sim`` front ends are
  ``hmocap_sim.commands.*``, which ``hmocap_ros/cli.py`` names by string and imports only when
  that command runs);
- an ``hmocap`` front end (``add_arguments``/``main_from_args``) outside ``commands/`` of either
  package.

A subprocess test imports ``hmocap_ros``, every node module and the ``hmocap`` command, and runs
some nodes' ``--help``, with ``hmocap_sim`` made unimportable.

An import names the most specific module of the package that exists: ``from a.b import c`` is an
edge to ``a/b/c.py`` when that file exists, else to ``a/b.py`` or ``a/b/__init__.py``. A package's
``__init__`` re-exporting its own modules is not a cycle with them: the edge from a submodule to
its parent package, which Python executes first, is not drawn.

Run as a script it prints the counts and the names (``python test/test_import_graph.py``).
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "hmocap_ros"
SIMULATOR = "hmocap_sim"


def module_name(path: Path) -> str:
    """Dotted module name of a source file (``hmocap_ros/a/__init__.py`` -> ``hmocap_ros.a``)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def package_modules() -> dict[str, Path]:
    """Every module of the product and of the simulator by its dotted name."""
    return {module_name(p): p for package in (PACKAGE, SIMULATOR)
            for p in sorted((ROOT / package).rglob("*.py"))}


def _is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def _absolute(module: str, path: Path, node: ast.ImportFrom) -> str:
    """The absolute module name of a (possibly relative) ``from ... import``."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not _is_package(path):
        base = base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of a dotted name that is a module of the package."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def imports_of(module: str, modules: dict[str, Path]) -> tuple[set[str], list[tuple[str, str]]]:
    """The package modules a module imports, and the private names it takes from them.

    Returns (imported modules, [(source module, private name), ...]).
    """
    path = modules[module]
    tree = ast.parse(path.read_text(), str(path))
    edges: set[str] = set()
    private: list[tuple[str, str]] = []
    aliases: dict[str, str] = {}          # local name -> package module it binds
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = _resolve(alias.name, modules)
                if target is None:
                    continue
                edges.add(target)
                if alias.asname:
                    aliases[alias.asname] = target
        elif isinstance(node, ast.ImportFrom):
            source = _absolute(module, path, node)
            base = _resolve(source, modules)
            if base is None:
                continue
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                if sub in modules:
                    edges.add(sub)
                    aliases[alias.asname or alias.name] = sub
                    continue
                edges.add(base)
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    private.append((base, alias.name))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                and node.value.id in aliases and node.attr.startswith("_")
                and not node.attr.startswith("__")):
            private.append((aliases[node.value.id], node.attr))
    parents = {module.rsplit(".", i)[0] for i in range(1, module.count(".") + 1)}
    edges -= parents | {module}
    private = [(m, n) for m, n in private if m != module]
    return edges, private


def import_graph() -> tuple[dict[str, set[str]], list[tuple[str, str, str]]]:
    """Module -> imported package modules, and every (importer, module, private name)."""
    modules = package_modules()
    graph: dict[str, set[str]] = {}
    private: list[tuple[str, str, str]] = []
    for module in modules:
        graph[module], taken = imports_of(module, modules)
        private += [(module, source, name) for source, name in taken]
    return graph, private


def folder_of(module: str) -> str:
    """The top-level subpackage (or top-level module) of hmocap_ros or hmocap_sim a module
    belongs to."""
    parts = module.split(".")
    return ".".join(parts[:2])


def folder_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The import graph between the top-level subpackages (and modules) of hmocap_ros."""
    folders: dict[str, set[str]] = defaultdict(set)
    for module, targets in graph.items():
        folders[folder_of(module)] |= {folder_of(t) for t in targets} - {folder_of(module)}
    return dict(folders)


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    counter = 0
    nodes = sorted(set(graph) | {t for ts in graph.values() for t in ts})
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    components.append(sorted(component))
    return sorted(components)


def cycle_in(component: list[str], graph: dict[str, set[str]]) -> list[str]:
    """One import cycle through a strongly connected component, for the failure message."""
    members = set(component)
    start = component[0]
    path, seen, node = [start], {start}, start
    while True:
        nxt = sorted(graph[node] & members)
        back = [n for n in nxt if n == start]
        if back and len(path) > 1:
            return path + [start]
        fresh = [n for n in nxt if n not in seen]
        node = fresh[0] if fresh else nxt[0]
        if node in seen:
            return path[path.index(node):] + [node]
        path.append(node)
        seen.add(node)


def _describe(components: list[list[str]], graph: dict[str, set[str]]) -> str:
    return "\n".join(" -> ".join(cycle_in(c, graph)) + f"  ({len(c)} modules)" for c in components)


def test_no_file_cycle():
    graph, _ = import_graph()
    components = strongly_connected(graph)
    assert not components, "modules that import one another:\n" + _describe(components, graph)


def test_no_folder_cycle():
    graph, _ = import_graph()
    folders = folder_graph(graph)
    components = strongly_connected(folders)
    details = []
    for component in components:
        members = set(component)
        details += [f"  {m} imports {t}" for m, ts in sorted(graph.items()) for t in sorted(ts)
                    if folder_of(m) in members and folder_of(t) in members
                    and folder_of(m) != folder_of(t)]
    assert not components, ("folders that import one another:\n" + _describe(components, folders)
                            + "\n" + "\n".join(details))


def test_no_private_import_across_modules():
    _, private = import_graph()
    assert not private, "private names taken from another module:\n" + "\n".join(
        f"  {importer} takes {source}.{name}" for importer, source, name in private)


def test_geometry_imports_nothing_of_the_package():
    """Camera geometry is the bottom layer: calibration, rendering, TF and tracking use it."""
    graph, _ = import_graph()
    above = sorted(t for m, ts in graph.items() if folder_of(m) == "hmocap_ros.geometry"
                   for t in ts if folder_of(t) != "hmocap_ros.geometry")
    assert not above, f"hmocap_ros.geometry imports {above}"


def test_the_product_never_imports_the_simulator():
    """No module of hmocap_ros imports hmocap_sim, at the top or inside a function."""
    graph, _ = import_graph()
    found = sorted(f"  {m} imports {t}" for m, ts in graph.items() if m.split(".")[0] == PACKAGE
                   for t in ts if t.split(".")[0] == SIMULATOR)
    assert not found, "the product imports the simulator:\n" + "\n".join(found)


def test_the_sim_commands_name_simulator_modules():
    """``hmocap sim KIND`` names a front end of hmocap_sim/commands/ that exists; no other
    group names the simulator."""
    from hmocap_ros.cli import COMMAND_GROUPS

    modules = package_modules()
    kinds = COMMAND_GROUPS["sim"][2]
    assert kinds
    for kind, (module, _help) in kinds.items():
        assert module.startswith(f"{SIMULATOR}.commands.") and module in modules, (kind, module)
    for group, (_, _, entries) in COMMAND_GROUPS.items():
        if group != "sim":
            assert not [m for m, _ in entries.values() if m.split(".")[0] == SIMULATOR], group


#: The two functions of an ``hmocap`` front end (:data:`hmocap_ros.cli.COMMAND_GROUPS`).
FRONT_END_FUNCTIONS = {"add_arguments", "main_from_args"}


def front_end_modules() -> dict[str, set[str]]:
    """Module -> the front-end functions (:data:`FRONT_END_FUNCTIONS`) it defines at top level."""
    found = {}
    for module, path in package_modules().items():
        names = {node.name for node in ast.parse(path.read_text(), str(path)).body
                 if isinstance(node, ast.FunctionDef) and node.name in FRONT_END_FUNCTIONS}
        if names:
            found[module] = names
    return found


def test_every_front_end_lives_in_commands():
    """Options, printing and exit status of every ``hmocap`` command are in ``commands/`` (the
    product's) or ``hmocap_sim/commands/`` (the simulator's); each such module has both
    functions, and every module the ``hmocap`` tables name is one of them."""
    from hmocap_ros.cli import COMMAND_GROUPS, COMMANDS

    found = front_end_modules()
    elsewhere = sorted(m for m in found if m.split(".")[1] != "commands")
    assert not elsewhere, f"front ends outside commands/: {elsewhere}"
    incomplete = sorted(m for m, names in found.items() if names != FRONT_END_FUNCTIONS)
    assert not incomplete, f"front ends without add_arguments or main_from_args: {incomplete}"
    named = ({m for _, _, kinds in COMMAND_GROUPS.values() for m, _ in kinds.values()}
             | {entry[0] for entry in COMMANDS.values()})
    assert named <= set(found), sorted(named - set(found))
    assert len(found) >= 20


def test_the_walk_sees_cycles_and_private_names():
    """The checks can fail: a made-up graph with a loop and a private import is caught."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert strongly_connected(graph) == [["a", "b", "c"]]
    assert cycle_in(["a", "b", "c"], graph) == ["a", "b", "c", "a"]
    assert folder_graph({"hmocap_ros.x.m": {"hmocap_ros.y.n"}, "hmocap_ros.y.n": {"hmocap_ros.x.k"},
                         "hmocap_ros.x.k": set()}) == {"hmocap_ros.x": {"hmocap_ros.y"},
                                                       "hmocap_ros.y": {"hmocap_ros.x"}}
    modules = package_modules()
    assert "hmocap_ros.tracking.body_tracker" in modules
    edges, _ = imports_of("hmocap_ros.tracking.body_tracker", modules)
    assert any(e.startswith("hmocap_ros.") for e in edges)
    edges, _ = imports_of("hmocap_sim.mocap_dataset", modules)   # the simulator's edges are seen
    assert any(e.startswith("hmocap_sim.") for e in edges) and any(e.startswith("hmocap_ros.") for e in edges)


if __name__ == "__main__":
    graph, private = import_graph()
    files = strongly_connected(graph)
    folders = folder_graph(graph)
    folder_cycles = strongly_connected(folders)
    statements = {(importer, source) for importer, source, _ in private}
    print(f"modules {len(graph)}, import edges {sum(map(len, graph.values()))}")
    print(f"file cycles (strongly connected groups) {len(files)}")
    print(_describe(files, graph))
    print(f"folder cycles {len(folder_cycles)}")
    print(_describe(folder_cycles, folders))
    print(f"private names taken {len(private)} by {len(statements)} (module, source) pairs")
    for importer, source, name in private:
        print(f"  {importer} takes {source}.{name}")
