"""The code map of docs/architecture.md, checked: no import cycle anywhere, the layers
import downward only, no product module imports the simulation package (the `sslfr`
dispatcher names its `sim` command by module name, the one documented edge) or the
test harness, node files stay thin."""
from __future__ import annotations

import ast
import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[2]      # src/

#: package -> the packages it may import (downward only; docs/architecture.md "Code map")
LAYERS = {
    'sslfr_common': set(),
    'sslfr_planner': {'sslfr_common'},
    'sslfr_drivers': {'sslfr_common'},
    'sslfr_safety': {'sslfr_common'},
    'sslfr_bringup': {'sslfr_common', 'sslfr_planner', 'sslfr_drivers', 'sslfr_safety'},
    'sslfr_recording': {'sslfr_common', 'sslfr_planner', 'sslfr_bringup'},
    'sslfr_web': {'sslfr_common', 'sslfr_planner', 'sslfr_safety', 'sslfr_recording'},
    'sslfr_gateway': {'sslfr_common', 'sslfr_recording'},
    'sslfr_field': {'sslfr_common', 'sslfr_planner', 'sslfr_drivers', 'sslfr_safety', 'sslfr_bringup',
                    'sslfr_recording', 'sslfr_web'},
    'sslfr_sim': {'sslfr_common', 'sslfr_planner', 'sslfr_drivers', 'sslfr_safety', 'sslfr_bringup',
                  'sslfr_recording', 'sslfr_web', 'sslfr_gateway', 'sslfr_field'},
}
#: the simulation package: imported by no product module
SIM = 'sslfr_sim'
#: the one product edge to it: the `sslfr` dispatcher's table entry naming the `sim`
#: command's module (a string, imported by importlib only when that command runs)
SIM_COMMAND = ('sim', 'sslfr_sim.sim_cli')
#: the test harness and the shared test helpers (tests/*.py, conftest.py)
TEST_MODULES = {p.stem for p in (SRC.parent / 'tests').glob('*.py')} | {'conftest'}
NODE_FILE_MAX_LINES = 300
#: the board link and the axis core: one class per job (issue 33)
CLASS_MAX_LINES = 300


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(SRC.glob('*/*/**/*.py')):
        rel = path.relative_to(SRC)
        parts = rel.parts[1:]                 # drop the ROS package directory
        if parts[0] in ('test', 'launch') or parts[0].endswith('.py'):
            continue
        name = '.'.join(parts)[:-3]
        out[name.removesuffix('.__init__')] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Project modules ``name`` imports (module-level and inside functions)."""
    is_pkg = path.name == '__init__.py'
    base = name.split('.') if is_pkg else name.split('.')[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                pkg = base[:len(base) - (node.level - 1)]
                mod = '.'.join(pkg + ([node.module] if node.module else []))
            else:
                mod = node.module or ''
            targets = [mod] + [f'{mod}.{a.name}' for a in node.names]
        for t in targets:
            while t and t not in MODULES:
                t = t.rpartition('.')[0]
            if t and t != name and not name.startswith(t + '.'):   # parent packages are not edges
                found.add(t)
    return found


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _cycles() -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
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
                out.append(sorted(comp))
    for v in GRAPH:
        if v not in index:
            visit(v)
    return out


def test_the_map_sees_every_package():
    assert {n.split('.')[0] for n in MODULES} == set(LAYERS)
    assert {p.name for p in SRC.iterdir() if (p / 'package.xml').is_file()} == set(LAYERS) | {'sslfr_interfaces'}
    assert len(MODULES) > 80


def test_no_import_cycle():
    assert _cycles() == []


def test_the_detector_finds_a_cycle():
    saved = dict(GRAPH)
    try:
        GRAPH['sslfr_common.contract'] = GRAPH['sslfr_common.contract'] | {'sslfr_common.node'}
        GRAPH['sslfr_common.node'] = GRAPH['sslfr_common.node'] | {'sslfr_common.contract'}
        assert ['sslfr_common.contract', 'sslfr_common.node'] in _cycles()
    finally:
        GRAPH.clear()
        GRAPH.update(saved)


def test_layers_import_downward_only():
    wrong = [f'{m} imports {t}' for m, deps in GRAPH.items() for t in deps
             if t.split('.')[0] != m.split('.')[0] and t.split('.')[0] not in LAYERS[m.split('.')[0]]]
    assert wrong == []


def test_product_code_never_imports_the_simulators():
    wrong = [f'{m} imports {t}' for m, deps in GRAPH.items() for t in deps
             if t.split('.')[0] == SIM and m.split('.')[0] != SIM]
    assert wrong == []


#: a module path in a string (``pkg.mod``, ``pkg.mod:attr``): what importlib can be handed
_MODULE_STRING = re.compile(r'^[a-z_][a-z0-9_]*(\.[a-z_][a-z0-9_]*)+(:[A-Za-z_][A-Za-z0-9_]*)?$')


def test_the_dispatcher_names_the_sim_command_and_no_other_simulation_module():
    """The one product reference to a module of sslfr_sim: `sslfr sim` in the
    dispatcher's table, by module name (importlib, only when that command runs). A
    module path of sslfr_sim in any other string of product code fails here."""
    from sslfr_bringup import cli
    assert [(k, v[0]) for k, v in cli.SUBCOMMANDS.items() if v[0].split('.')[0] == SIM] == [SIM_COMMAND]
    found = [f'{name}: {node.value}' for name, path in MODULES.items() if name.split('.')[0] != SIM
             for node in ast.walk(ast.parse(path.read_text(), str(path)))
             if isinstance(node, ast.Constant) and isinstance(node.value, str)
             and _MODULE_STRING.match(node.value) and node.value.split('.')[0] == SIM]
    assert found == [f'sslfr_bringup.cli: {SIM_COMMAND[1]}']


def test_product_code_never_imports_the_test_harness():
    wrong = []
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or '']
            else:
                continue
            wrong += [f'{name} imports {n}' for n in names if n.split('.')[0] in TEST_MODULES]
    assert wrong == []


def test_node_files_are_thin():
    fat = {str(p.relative_to(SRC)): n for p in SRC.glob('*/*/**/*_node.py')
           if (n := len(p.read_text().splitlines())) >= NODE_FILE_MAX_LINES}      # under 300
    assert fat == {}


def test_the_board_link_and_axis_core_classes_are_each_under_300_lines():
    """The board link and the axis driver's core, split by job (one class each)."""
    import ast
    fat = {}
    for path in (*SRC.glob('sslfr_drivers/sslfr_drivers/link/*.py'), *SRC.glob('sslfr_drivers/sslfr_drivers/axis/*.py')):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and node.end_lineno - node.lineno + 1 >= CLASS_MAX_LINES:
                fat[f'{path.name}:{node.name}'] = node.end_lineno - node.lineno + 1
    assert fat == {}


def test_one_conftest_at_the_root():
    """Tests import the harness as ``from conftest import ...``: a second conftest.py
    anywhere under the test paths would be that module for some xdist workers."""
    others = sorted(str(p.relative_to(SRC.parent)) for p in (*SRC.rglob('conftest.py'),
                                                               *(SRC.parent / 'tests').rglob('conftest.py')))
    assert others == [], others
