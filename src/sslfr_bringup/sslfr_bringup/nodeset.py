"""The node set of the tracker: load ``config/nodeset.yaml`` and turn it into process
command lines (``./sslfr up``, ``./sslfr sim``) or launch entries (tracker.launch.py).

Pure Python (PyYAML only, no rclpy), so the launch file on a Pi, the supervisor here
and the unit tests all read the same description the same way.

Vocabulary
----------
node     one ROS node process (:class:`NodeSpec`): executable, name, role parameters,
         lifecycle or not, start order and stop group.
process  one OS process of a *layout* (:class:`ProcessSpec`): one node (``separate``) or
         several nodes composed in one process and one executor (``composed``: the
         ``composed`` executable, each node built from its ``component`` class with its
         own name, namespace, params files and parameters); critical nodes (safety)
         always alone.
board    a device a node talks to (:class:`BoardSpec`): its udev name on the Pi and the
         simulated board process that replaces it in ``./sslfr sim``.
config   the site's ROS params file (``almeria_sslfr.yaml`` ...): node tuning and the
         shared ``site.*`` keys. Looked up in this package's config directory when
         given by bare name.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml
from sslfr_common.files import user_path
from sslfr_common.contract import MIRRORS, namespace_remaps
from sslfr_common.params import flatten as flatten_params

from sslfr_bringup.dds_profile import with_graph_partition, with_profile
from sslfr_bringup.local_discovery import field_client
from sslfr_bringup.liveness import DEFAULT_STARTUP_TIMEOUT, DEFAULT_TIMEOUT, check_bounds

#: Parameter that receives a board's serial port (pyserial URL or device path).
PORT_PARAM = 'port'
NODESET_FILE = 'nodeset.yaml'


class NodeSetError(ValueError):
    """The node-set description or a site config is invalid (message says where)."""


@dataclass(frozen=True)
class BoardSpec:
    """A board: stable device name on the Pi and its simulated replacement."""

    name: str
    device: str
    sim_package: str | None = None
    sim_executable: str | None = None
    sim_args: tuple[str, ...] = ()


@dataclass(frozen=True)
class NodeSpec:
    """One node process of the set."""

    name: str
    package: str
    executable: str
    lifecycle: bool = False
    critical: bool = False
    start: int = 0
    stop: int = 1
    board: str | None = None
    parameters: Mapping[str, Any] = field(default_factory=dict)
    remaps: Mapping[str, str] = field(default_factory=dict)
    params: str | None = None      # 'module:attribute' of its parameter table (see node_table)
    component: str | None = None   # 'module:Class' of its node (composed layouts)


@dataclass(frozen=True)
class ProcessSpec:
    """One process of a layout: ``name`` (the node's, or the group's) and its nodes in
    start order (the axis drivers first: their ``on_exit`` stops the motors first)."""

    name: str
    nodes: tuple[NodeSpec, ...]

    @property
    def composed(self) -> bool:
        return len(self.nodes) > 1


@dataclass(frozen=True)
class NodeSet:
    """The whole description (see config/nodeset.yaml for the meaning of each key)."""

    nodes: tuple[NodeSpec, ...]
    boards: Mapping[str, BoardSpec]
    config: str = 'almeria_sslfr.yaml'
    domain_id: int = 42
    discovery_range: str = 'LOCALHOST'
    namespace: str = ''
    restart_backoff: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0, 16.0, 30.0)
    stable_after: float = 60.0
    stop_timeout: float = 5.0
    watchdog_timeout: float = DEFAULT_TIMEOUT          # [s] executor beat bound (sslfr_bringup.liveness)
    watchdog_startup: float = DEFAULT_STARTUP_TIMEOUT  # [s] start to first beat
    sim: Mapping[str, Any] = field(default_factory=dict)
    #: process layouts: name -> ((group name, (node names...)), ...); nodes in no group run alone
    layouts: Mapping[str, tuple] = field(default_factory=lambda: {'separate': ()})
    layout: str = 'separate'                  # the default layout
    #: the whole description's nodes when this is a selection (``only``/``without``):
    #: a site config is judged against all of them, not the selection
    all_nodes: tuple[NodeSpec, ...] = ()
    path: Path | None = None
    #: the simulated axis board of each drive kind: {kind: {package, executable, args}}
    drive_sims: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    #: the collector description of a config that names none (relative to config_dir());
    #: after :func:`for_config`: the description the set was narrowed to (absolute)
    collector: str = 'collectors/almeria_three_movement.yaml'

    def node(self, name: str) -> NodeSpec:
        """Return the node called ``name`` (KeyError with the known names)."""
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(f'no node {name!r} in the node set (known: {", ".join(n.name for n in self.nodes)})')

    def start_order(self) -> list[NodeSpec]:
        """Nodes in start order (stable within one ``start`` value)."""
        return sorted(self.nodes, key=lambda n: n.start)

    def stop_groups(self) -> list[list[NodeSpec]]:
        """Nodes grouped for an ordered stop: group 0 (the axes) first."""
        groups: dict[int, list[NodeSpec]] = {}
        for n in self.nodes:
            groups.setdefault(n.stop, []).append(n)
        return [groups[k] for k in sorted(groups)]

    def lifecycle_nodes(self) -> list[NodeSpec]:
        return [n for n in self.nodes if n.lifecycle]

    def processes(self, layout: str | None = None) -> list[ProcessSpec]:
        """The processes of ``layout`` (default: the node set's) in start order: each
        group of the layout with the nodes of this (selected) set, the other nodes alone.
        A group left with one node runs it alone; nodes within a process: stop group,
        then start order. KeyError for an unknown layout."""
        name = layout or self.layout
        if name not in self.layouts:
            raise KeyError(f'no layout {name!r} in the node set (known: {", ".join(self.layouts)})')
        mine = {n.name: n for n in self.start_order()}
        out, grouped = [], set()
        for group, members in self.layouts[name]:
            # stop group first (the axes' on_exit stops the motors first), then start order
            nodes = tuple(sorted((mine[m] for m in members if m in mine), key=lambda n: (n.stop, n.start)))
            grouped.update(n.name for n in nodes)
            if len(nodes) > 1:
                out.append(ProcessSpec(group, nodes))
            elif nodes:
                out.append(ProcessSpec(nodes[0].name, nodes))
        out += [ProcessSpec(n.name, (n,)) for n in mine.values() if n.name not in grouped]
        return sorted(out, key=lambda p: min(n.start for n in p.nodes))

    def only(self, names: Iterable[str]) -> 'NodeSet':
        """A copy restricted to ``names`` (unknown names raise KeyError)."""
        keep = set(names)
        for name in keep:
            self.node(name)
        return NodeSet(**{**self.__dict__, 'nodes': tuple(n for n in self.nodes if n.name in keep),
                          'all_nodes': self.all_nodes or self.nodes})

    def without(self, names: Iterable[str]) -> 'NodeSet':
        drop = set(names)
        return NodeSet(**{**self.__dict__, 'nodes': tuple(n for n in self.nodes if n.name not in drop),
                          'all_nodes': self.all_nodes or self.nodes})


# ---------------------------------------------------------------------------------
# locating files

def config_dir() -> Path:
    """This package's config directory: the source tree when present (a developer
    checkout or a --symlink-install build), else the installed share directory."""
    here = Path(__file__).resolve().parent.parent / 'config'
    if (here / NODESET_FILE).is_file():
        return here
    try:  # an installed (non-symlink) build on a Pi
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory('sslfr_bringup')) / 'config'
    except Exception:  # noqa: BLE001 - fall back to the source location
        return here


def resolve_config(name: str | os.PathLike | None, default: str = 'almeria_sslfr.yaml') -> Path:
    """Return the params file for ``name``: a path as given when it exists, else a
    file of that name (``.yaml`` optional) in :func:`config_dir`."""
    name = str(name) if name else default

    def is_file(path: Path) -> bool:        # a name too long or with a NUL byte is no file
        try:
            return path.is_file()
        except (OSError, ValueError):
            return False
    p = user_path(name)
    if is_file(p):
        return p.resolve()
    for cand in (config_dir() / name, config_dir() / f'{name}.yaml'):
        if is_file(cand):
            return cand
    known = ', '.join(sorted(f.name for f in config_dir().glob('*.yaml') if f.name != NODESET_FILE))
    raise NodeSetError(f'config {name[:200]!r} not found (as a path or in {config_dir()}; known: {known})')


# ---------------------------------------------------------------------------------
# loading

def _as_tuple_str(value, where: str) -> tuple[str, ...]:
    if value is None:
        return ()
    if not isinstance(value, list):
        raise NodeSetError(f'{where}: expected a list, got {value!r}')
    return tuple(str(v) for v in value)


def parse(data: Mapping[str, Any], path: Path | None = None) -> NodeSet:
    """Validate and convert the YAML document ``data`` into a :class:`NodeSet`."""
    if not isinstance(data, Mapping):
        raise NodeSetError('node set: top level must be a mapping')
    boards: dict[str, BoardSpec] = {}
    for bname, b in (data.get('boards') or {}).items():
        if not isinstance(b, Mapping) or 'device' not in b:
            raise NodeSetError(f'boards.{bname}: needs a device')
        sim = b.get('sim') or {}
        boards[str(bname)] = BoardSpec(
            name=str(bname), device=str(b['device']),
            sim_package=sim.get('package'), sim_executable=sim.get('executable'),
            sim_args=_as_tuple_str(sim.get('args'), f'boards.{bname}.sim.args'))
    nodes: list[NodeSpec] = []
    seen: set[str] = set()
    for i, n in enumerate(data.get('nodes') or []):
        where = f'nodes[{i}]'
        if not isinstance(n, Mapping):
            raise NodeSetError(f'{where}: must be a mapping')
        for key in ('name', 'package', 'executable'):
            if not n.get(key):
                raise NodeSetError(f'{where}: missing {key}')
        name = str(n['name'])
        if name in seen:
            raise NodeSetError(f'{where}: duplicate node name {name!r}')
        seen.add(name)
        board = n.get('board')
        if board is not None and board not in boards:
            raise NodeSetError(f'{where} ({name}): unknown board {board!r}')
        params = dict(n.get('parameters') or {})
        remaps = {str(k): str(v) for k, v in (n.get('remaps') or {}).items()}
        try:
            start, stop = int(n.get('start', 0)), int(n.get('stop', 1))
        except (TypeError, ValueError) as exc:
            raise NodeSetError(f'{where} ({name}): start/stop must be integers') from exc
        nodes.append(NodeSpec(name=name, package=str(n['package']), executable=str(n['executable']),
                              lifecycle=bool(n.get('lifecycle', False)),
                              critical=bool(n.get('critical', False)), start=start, stop=stop,
                              board=board, parameters=params, remaps=remaps,
                              params=str(n['params']) if n.get('params') else None,
                              component=str(n['component']) if n.get('component') else None))
    if not nodes:
        raise NodeSetError('node set: no nodes')
    d = data.get('defaults') or {}
    domain_id = int(d.get('domain_id', 42))
    if not 0 < domain_id <= 232:
        raise NodeSetError(f'defaults.domain_id {domain_id} outside 1..232 (0 is every robot\'s default)')
    backoff = tuple(float(x) for x in d.get('restart_backoff', (1.0, 2.0, 4.0, 8.0, 16.0, 30.0)))
    if not backoff or any(x <= 0 for x in backoff):
        raise NodeSetError('defaults.restart_backoff must be positive seconds')
    try:
        watchdog = (float(d.get('watchdog_timeout', DEFAULT_TIMEOUT)),
                    float(d.get('watchdog_startup', DEFAULT_STARTUP_TIMEOUT)))
    except (TypeError, ValueError) as exc:
        raise NodeSetError(f'defaults.watchdog_timeout / watchdog_startup must be seconds: {exc}') from None
    problems = check_bounds(*watchdog)
    if problems:
        raise NodeSetError('defaults.' + '; defaults.'.join(problems))
    drive_sims = {}
    for kind, sim in (data.get('drive_sims') or {}).items():
        if not isinstance(sim, Mapping) or not sim.get('package') or not sim.get('executable'):
            raise NodeSetError(f'drive_sims.{kind}: needs package, executable and args')
        drive_sims[str(kind)] = {'package': str(sim['package']), 'executable': str(sim['executable']),
                                 'args': _as_tuple_str(sim.get('args'), f'drive_sims.{kind}.args')}
    return NodeSet(nodes=tuple(nodes), boards=boards, config=str(d.get('config', 'almeria_sslfr.yaml')),
                   drive_sims=drive_sims,
                   collector=str(d.get('collector', 'collectors/almeria_three_movement.yaml')),
                   domain_id=domain_id, discovery_range=str(d.get('discovery_range', 'LOCALHOST')),
                   namespace=str(d.get('namespace') or ''), restart_backoff=backoff,
                   stable_after=float(d.get('stable_after', 60.0)),
                   stop_timeout=float(d.get('stop_timeout', 5.0)),
                   watchdog_timeout=watchdog[0], watchdog_startup=watchdog[1],
                   sim=dict(data.get('sim') or {}), path=path,
                   **_parse_layouts(data, {n.name: n for n in nodes}))


def _parse_layouts(data: Mapping[str, Any], nodes: Mapping[str, NodeSpec]) -> dict:
    """``layouts:`` (name -> {group: [node names]}) and ``defaults.layout``: every node
    named once, known, with a ``component``, and never a critical node in a group (the
    safety supervisor always has its own process: a crash elsewhere cannot take it down)."""
    layouts: dict[str, tuple] = {'separate': ()}
    for lname, groups in (data.get('layouts') or {}).items():
        where = f'layouts.{lname}'
        if groups in (None, {}):
            layouts[str(lname)] = ()
            continue
        if not isinstance(groups, Mapping):
            raise NodeSetError(f'{where}: a mapping of process names to node lists')
        seen: set[str] = set()
        out = []
        for gname, members in groups.items():
            members = _as_tuple_str(members, f'{where}.{gname}')
            if str(gname) in nodes and members != (str(gname),):
                raise NodeSetError(f'{where}.{gname}: a process is not named after a node it does not run alone')
            for m in members:
                if m not in nodes:
                    raise NodeSetError(f'{where}.{gname}: unknown node {m!r}')
                if m in seen:
                    raise NodeSetError(f'{where}.{gname}: node {m!r} is in two processes')
                seen.add(m)
                if len(members) > 1 and nodes[m].critical:
                    raise NodeSetError(f'{where}.{gname}: {m} is critical and must run in its own process')
                if len(members) > 1 and not nodes[m].component:
                    raise NodeSetError(f'{where}.{gname}: {m} has no component (module:Class) to compose')
            out.append((str(gname), members))
        layouts[str(lname)] = tuple(out)
    layout = str((data.get('defaults') or {}).get('layout', 'separate'))
    if layout not in layouts:
        raise NodeSetError(f'defaults.layout {layout!r}: no such layout (known: {", ".join(layouts)})')
    return {'layouts': layouts, 'layout': layout}


def load(path: str | os.PathLike | None = None) -> NodeSet:
    """Load the node set (default: ``config/nodeset.yaml`` of this package)."""
    p = Path(path) if path else config_dir() / NODESET_FILE
    return parse(_yaml_document(p, 'node set', f'node set {p}'), p)


def for_config(ns: NodeSet, config: str | os.PathLike, namespace: str | None = None) -> NodeSet:
    """``ns`` narrowed to the collector the site config ``config`` names (its
    description: :mod:`sslfr_bringup.collector_set`); NodeSetError when the config is
    unreadable or the description invalid (nothing started)."""
    from sslfr_planner import description as desc_mod

    from sslfr_bringup import collector_set
    nsp = ns.namespace if namespace is None else namespace
    planner = node_params(for_namespace(read_params(config), nsp), 'planner', nsp)
    name = planner.get(DESCRIPTION_KEY)
    path = desc_mod.resolve(name, Path(config).parent) if isinstance(name, str) and name \
        else desc_mod.resolve(ns.collector, config_dir())
    try:
        return collector_set.for_collector(ns, desc_mod.load(path), planner)
    except desc_mod.DescriptionError as exc:
        raise NodeSetError(f'{config}: {DESCRIPTION_KEY} {str(path)!r}:\n  ' + '\n  '.join(exc.problems)) from None
    except ValueError as exc:
        raise NodeSetError(str(exc)) from None


def _yaml_document(path, what: str, label: str):
    """The YAML document of text file ``path``; :class:`NodeSetError` (``label``: the
    line's subject) if it is unreadable, not UTF-8 text or not YAML (with the YAML line)."""
    from sslfr_planner.cli_input import CliError, read_text_file
    try:
        text = read_text_file(path, what)
    except CliError as exc:
        raise NodeSetError(str(exc)) from None
    try:
        return yaml.safe_load(text)
    except RecursionError:
        raise NodeSetError(f'{label}: YAML nested too deeply') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        raise NodeSetError(f'{label}: invalid YAML{f" at line {mark.line + 1}" if mark else ""}') from None


def read_params(path: str | os.PathLike) -> dict:
    """Read a ROS params file; raise :class:`NodeSetError` with the reason if it is not
    one (not UTF-8 text, not YAML, not a mapping of sections with ``ros__parameters``
    mappings): the line names the file and, where there is one, the YAML line."""
    data = _yaml_document(path, 'config', f'{path}') or {}
    if not isinstance(data, dict):
        raise NodeSetError(f'{path}: a params file is a mapping of node names')
    for key, section in data.items():
        if not isinstance(section, dict) or 'ros__parameters' not in section:
            raise NodeSetError(f'{path}: section {key!r} has no ros__parameters')
        if not isinstance(section['ros__parameters'], dict):
            raise NodeSetError(f'{path}: section {key!r}: ros__parameters must be a mapping of parameters')
    return data


def section_matches(key: str, fqn: str) -> bool:
    """Whether a params-file section ``key`` applies to the node ``fqn`` (``/ns/name``),
    by rcl's rules (checked against rclpy in the tests): a key without a leading
    ``/`` is taken from the root (``planner`` is ``/planner``: root namespace only);
    ``*`` matches one name token, ``**`` any number of tokens (``/**`` every node,
    ``/**/planner`` a planner in any namespace)."""
    pattern = [t for t in ('/' + key.lstrip('/')).split('/') if t]
    name = [t for t in fqn.split('/') if t]

    def match(i: int, j: int) -> bool:
        if i == len(pattern):
            return j == len(name)
        if pattern[i] == '**':
            return any(match(i + 1, k) for k in range(j, len(name) + 1))
        return j < len(name) and pattern[i] in ('*', name[j]) and match(i + 1, j + 1)
    return match(0, 0)


def node_params(params: Mapping[str, Any], node: str, namespace: str = '') -> dict:
    """The parameters a params file gives node ``node`` in ``namespace``, as rcl does:
    every section whose key matches the node's fully qualified name
    (:func:`section_matches`), in file order, a later section winning."""
    out: dict = {}
    fqn = f'/{namespace.strip("/")}/{node}' if namespace.strip('/') else f'/{node}'
    for key, section in params.items():
        if isinstance(section, Mapping) and section_matches(str(key), fqn):
            out.update(flatten_params(section.get('ros__parameters') or {}))
    return out


def for_namespace(params: Mapping[str, Any], namespace: str) -> dict:
    """A site config made for ONE collector, moved under ``namespace``: its sections
    keyed by a bare node name (``planner``, which rcl matches only in the root
    namespace) are re-keyed ``/<namespace>/planner``; keys that start with ``/`` or
    hold wildcards (``/**``, ``/**/planner``) are kept as written. So several
    collectors, each with its own config under its own namespace, share one domain."""
    nsp = namespace.strip('/')
    if not nsp:
        return dict(params)
    out = {}
    for key, section in params.items():
        k = str(key)
        bare = not k.startswith('/') and '*' not in k
        out[f'/{nsp}/{k}' if bare else k] = section
    return out


#: Parameters every ROS 2 node has (rcl/rclpy): never refused in a site config.
ROS_PARAMETERS = ('use_sim_time', 'start_type_description_service')
ROS_PARAMETER_PREFIXES = ('qos_overrides.',)


def node_table(node: NodeSpec):
    """The node's parameter table (:class:`sslfr_common.params.ParamTable`), the one its
    node declares: ``params: module:attribute`` in the node set, the attribute a table or
    a function of the node's role parameters (e.g. the axis). None when not given."""
    if not node.params:
        return None
    import importlib
    from sslfr_common.params import ParamTable
    module, _, attr = node.params.partition(':')
    try:
        obj = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise NodeSetError(f'node {node.name}: params {node.params!r}: {exc}') from exc
    return obj if isinstance(obj, ParamTable) else obj(**node.parameters)


def check_config(ns: NodeSet, params: Mapping[str, Any], namespace: str | None = None,
                 where: str = 'config') -> list[str]:
    """Every problem of a site config for the node set, checked with the parameter
    tables the nodes declare (one source), before anything starts: sections that apply
    to no node (a misspelt node name), keys no node it applies to declares (a misspelt
    key, with the closest names), values of the wrong YAML type or out of range, and
    the nodes' own cross-checks on what they would receive, and the collector
    description the config names (:func:`collector_problems`; ``where`` is the config's
    path, the base of a relative description name). Each line names the file, the
    section or node, the key, its value and what is allowed."""
    import difflib
    nsp = ns.namespace if namespace is None else namespace
    doc = for_namespace(params, nsp)
    nodes = ns.all_nodes or ns.nodes
    fqn = {n.name: fully_qualified_name(n, nsp) for n in nodes}
    tables = {n.name: node_table(n) for n in nodes}
    errors: list[str] = []
    for key, section in doc.items():
        matched = [n for n in nodes if section_matches(str(key), fqn[n.name])]
        if not matched:
            close = difflib.get_close_matches(str(key).strip('/'), [n.name for n in nodes], n=2)
            hint = f' (did you mean {" or ".join(close)}?)' if close else ''
            errors.append(f'{where}: section {key!r} applies to no node of the node set{hint}; '
                          f'nodes: {", ".join(n.name for n in nodes)}')
            continue
        known = [tables[n.name] for n in matched]
        if any(t is None for t in known):
            continue                  # a node without a table: cannot judge its keys
        for name in flatten_params(section.get('ros__parameters') or {}):
            if name in ROS_PARAMETERS or name.startswith(ROS_PARAMETER_PREFIXES) or any(name in t for t in known):
                continue
            names = sorted({k for t in known for k in t.names})
            close = difflib.get_close_matches(name, names, n=2)
            hint = f' (did you mean {" or ".join(close)}?)' if close else ''
            errors.append(f'{where}: section {key!r}: {name}: not a parameter of '
                          f'{" / ".join(n.name for n in matched)}{hint}')
    seen = set()
    for n in nodes:
        table = tables[n.name]
        if table is None:
            continue
        values = {k: v for k, v in {**node_params(doc, n.name, nsp), **n.parameters}.items() if k in table}
        for err in table.check_overrides(values):
            line = f'{where}: {n.name}: {err}'
            if err not in seen:
                errors.append(line)
                seen.add(err)
    errors.extend(collector_problems(doc, nsp, where))
    from sslfr_bringup.collector_set import contradictions
    errors.extend(contradictions(ns, lambda name: node_params(doc, name, nsp), where))
    return errors


#: the planner parameter that names the collector description (docs/collectors.md)
DESCRIPTION_KEY = 'collector.description'


def collector_problems(doc: Mapping[str, Any], namespace: str, where: str) -> list[str]:
    """Problems of the collector description a site config names (``collector.description``
    for the planner, relative to the config's directory): every problem of the file
    (:func:`sslfr_planner.description.load`, each naming the file and key) and every
    planner ``collector.*`` value of the config that contradicts it, and wind supervision
    (``absorber_board`` ``anemometer_pin`` >= 0 or ``safety`` ``wind.enabled``) on a
    collector whose description lists no anemometer."""
    from sslfr_planner import description as desc_mod
    name = node_params(doc, 'planner', namespace).get(DESCRIPTION_KEY)
    if not name or not isinstance(name, str):
        return []
    path = desc_mod.resolve(name, Path(where).parent)
    try:
        desc = desc_mod.load(path)
    except desc_mod.DescriptionError as exc:
        return [f'{where}: {DESCRIPTION_KEY} {name!r}: {p}' for p in exc.problems]
    errors = []
    for key, value in node_params(doc, 'planner', namespace).items():
        expected = description_value(desc, key)
        if expected is None:
            continue
        same = value == expected if isinstance(expected, (bool, str)) else \
            isinstance(value, (int, float)) and not isinstance(value, bool) and abs(float(value) - expected) <= 1e-9 + 1e-6 * abs(expected)
        if not same:
            errors.append(f'{where}: planner: {key}: {value!r} contradicts the collector description '
                          f'{path}: {expected!r}')
    if not any(s.kind == 'anemometer' for s in desc.sensors.values()):
        pin = node_params(doc, 'absorber_board', namespace).get('anemometer_pin', -1)
        if isinstance(pin, int) and not isinstance(pin, bool) and pin >= 0:
            errors.append(f'{where}: absorber_board: anemometer_pin: {pin} but the collector description '
                          f'{path} lists no anemometer (sensors: kind anemometer)')
        if node_params(doc, 'safety', namespace).get('wind.enabled') is True:
            errors.append(f'{where}: safety: wind.enabled: true but the collector description {path} '
                          f'lists no anemometer (sensors: kind anemometer)')
    return errors + thermal_problems(desc, node_params(doc, 'absorber_board', namespace), where, path)


def thermal_problems(desc, absorber: Mapping[str, Any], where: str, path) -> list[str]:
    """A flow meter counted (``absorber_board`` ``flow_meter_pin`` >= 0) on a collector
    whose description lists no ``flow_meter`` sensor, and an ``aperture_area`` that is
    not the description's lines x line_width x line_length."""
    from sslfr_planner.analysis.ideal import aperture_area
    errors = []
    pin = absorber.get('flow_meter_pin', -1)
    if isinstance(pin, int) and not isinstance(pin, bool) and pin >= 0 and \
            not any(s.kind == 'flow_meter' for s in desc.sensors.values()):
        errors.append(f'{where}: absorber_board: flow_meter_pin: {pin} but the collector description '
                      f'{path} lists no flow meter (sensors: kind flow_meter)')
    area = absorber.get('aperture_area')
    expected = aperture_area(desc)
    if isinstance(area, (int, float)) and not isinstance(area, bool) and area != 0 and \
            abs(float(area) - expected) > 1e-6 * expected:
        errors.append(f'{where}: absorber_board: aperture_area: {area!r} contradicts the collector description '
                      f'{path}: lines x line_width x line_length = {expected!r} m^2')
    return errors


def description_value(desc, key: str):
    """The value a planner ``collector.*`` parameter must have for description ``desc``
    (None: the description does not fix it)."""
    import math
    o = desc.optics
    values = {'collector.law': desc.longitudinal_law, 'collector.azimuth': o.azimuth,
              'collector.n_per_side': o.n_per_side, 'collector.central_mirror': o.central_line,
              'collector.mirror_width': o.line_width, 'collector.gap': o.gap,
              'collector.receiver_height': o.receiver_height - o.tube_diameter / 2.0,
              'collector.tube_diameter': o.tube_diameter}
    m = desc.movements.get(MIRRORS)
    if m is not None and m.law == 'seed003_linkage':
        values['collector.tracking_step'] = m.law_params['step_s']
    v = values.get(key)
    return float(v) if isinstance(v, float) and math.isfinite(v) else v


# ---------------------------------------------------------------------------------
# what to run

def format_param(value: Any) -> str:
    """Format ``value`` for ``-p name:=value`` (YAML syntax, as rcl parses it)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return '[' + ','.join(format_param(v) if not isinstance(v, str) else repr(v) for v in value) + ']'
    return str(value)


def checked_params(ns: NodeSet, config: str | os.PathLike, namespace: str | None = None) -> dict:
    """The parsed site config, judged by :func:`check_config` for ``ns``: NodeSetError
    listing every problem ("nothing started")."""
    params = read_params(config)
    problems = check_config(ns, params, namespace, where=str(config))
    if problems:
        raise NodeSetError('invalid site config, nothing started:\n  ' + '\n  '.join(problems))
    return absolute_description(params, config)


def absolute_description(params: Mapping[str, Any], config: str | os.PathLike) -> dict:
    """``params`` with every relative ``collector.description`` made absolute (relative
    to the config's directory), so a copy of the config written elsewhere (a namespace's
    site.params.yaml) still names the same file."""
    out = {}
    for key, section in params.items():
        values = section.get('ros__parameters') if isinstance(section, Mapping) else None
        name = values.get(DESCRIPTION_KEY) if isinstance(values, Mapping) else None
        if isinstance(name, str) and name and not user_path(name).is_absolute():
            section = {**section, 'ros__parameters': {**values, DESCRIPTION_KEY: str(
                (Path(config).resolve().parent / name).resolve())}}
        out[key] = section
    return out


def site_config(config: str | os.PathLike, namespace: str, write_dir: str | os.PathLike,
                ns: NodeSet | None = None, params: Mapping[str, Any] | None = None) -> tuple[Path, dict]:
    """The params file to hand the nodes and its parsed content: ``config`` itself
    in the root namespace; under a namespace, a copy moved there
    (:func:`for_namespace`) written to ``write_dir/site.params.yaml``. With ``ns`` the
    config is checked first (:func:`checked_params`), unless ``params`` is the
    content a caller has already checked."""
    if params is None:
        params = checked_params(ns, config, namespace) if ns is not None else read_params(config)
    if not namespace.strip('/'):
        return Path(config), params
    params = for_namespace(params, namespace)
    out = Path(write_dir) / 'site.params.yaml'
    out.write_text(yaml.safe_dump(params, sort_keys=False))
    return out, params


def node_port(ns: NodeSet, node: NodeSpec, params: Mapping[str, Any] | None = None,
              sim_ports: Mapping[str, str] | None = None, namespace: str | None = None) -> str | None:
    """The ``port`` to hand ``node`` on the command line, or None.

    Simulation: the simulated board's pty path always. Real boards: the board's udev
    device, unless the site config already sets ``port`` for this node (the config wins).
    """
    if node.board is None:
        return None
    if sim_ports is not None:
        return sim_ports.get(node.board)
    nsp = ns.namespace if namespace is None else namespace
    if params is not None and PORT_PARAM in node_params(params, node.name, nsp):
        return None
    return ns.boards[node.board].device


def node_overrides(ns: NodeSet, node: NodeSpec, params: Mapping[str, Any] | None = None,
                   sim_ports: Mapping[str, str] | None = None, use_sim_time: bool = False,
                   extra: Mapping[str, Any] | None = None, namespace: str | None = None) -> dict:
    """Parameters the node set imposes on ``node`` on top of the site config, in
    increasing precedence: role parameters, ``port``, ``use_sim_time``, ``extra``."""
    out = dict(node.parameters)
    port = node_port(ns, node, params, sim_ports, namespace)
    if port:
        out[PORT_PARAM] = port
    if use_sim_time:
        out['use_sim_time'] = True
    out.update(extra or {})
    return out


def fully_qualified_name(node: NodeSpec, namespace: str = '') -> str:
    """``/ns/name`` as rcl matches it against params-file keys."""
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    return f'{ns}/{node.name}'


def overrides_document(ns: NodeSet, node: NodeSpec, overrides: Mapping[str, Any],
                       namespace: str | None = None) -> dict:
    """A params-file document giving ``overrides`` to ``node`` alone.

    They must be a node-specific params file passed AFTER the site config: rclpy
    applies ``-p`` command-line values as ``/**`` (wildcard) parameters, which the
    config's node section would override, whereas between two files naming the same
    node the later one wins.
    """
    nsp = ns.namespace if namespace is None else namespace
    return {fully_qualified_name(node, nsp): {'ros__parameters': dict(overrides)}}


def remaps(node: NodeSpec, namespace: str) -> dict[str, str]:
    """``node``'s remappings: the node set's, then those of a collector in ``namespace``
    (:func:`sslfr_common.contract.namespace_remaps`)."""
    return {**node.remaps, **namespace_remaps(namespace)}


def ros_args(ns: NodeSet, node: NodeSpec, config: str | os.PathLike, *,
             overrides_file: str | os.PathLike | None = None, namespace: str | None = None,
             log_level: str | None = None) -> list[str]:
    """The ``--ros-args ...`` part of ``node``'s command line: name, namespace, the
    site config, then the node's overrides file (see :func:`overrides_document`)."""
    nsp = ns.namespace if namespace is None else namespace
    args = ['--ros-args', '-r', f'__node:={node.name}']
    if nsp:
        args += ['-r', f'__ns:={nsp}']
    args += ['--params-file', str(config)]
    if overrides_file:
        args += ['--params-file', str(overrides_file)]
    for src, dst in remaps(node, nsp).items():
        args += ['-r', f'{src}:={dst}']
    if log_level:
        args += ['--log-level', log_level]
    return args


#: The executable running a composed process (sslfr_bringup/composed.py).
COMPOSED = ('sslfr_bringup', 'composed')


def composed_args(proc: ProcessSpec, node_args: Mapping[str, list[str]]) -> list[str]:
    """Arguments of the ``composed`` executable for ``proc``: ``--process NAME`` then,
    per node, ``--node module:Class --ros-args ...`` (its own :func:`ros_args`: name,
    namespace, params files, remaps). Each node reads only its own ``--ros-args``."""
    out = ['--process', proc.name]
    for node in proc.nodes:
        out += ['--node', str(node.component), *node_args[node.name]]
    return out


def launch_entries(ns: NodeSet, config: str | os.PathLike, *, namespace: str | None = None,
                   write_dir: str | os.PathLike | None = None, use_sim_time: bool = False,
                   layout: str | None = None) -> list[dict]:
    """What tracker.launch.py turns into ``launch_ros`` actions, in start order, one
    per process of ``layout`` (default: the node set's). A composed process is the
    ``composed`` executable with ``arguments`` (:func:`composed_args`; its nodes'
    overrides written to ``write_dir``), ``name`` None, ``nodes`` the node names.

    Each entry: package, executable, name, namespace, parameters (a list: the site
    params file, moved under the namespace as :func:`site_config` does, then a dict of
    role parameters, port and use_sim_time), remappings (list of pairs), lifecycle
    (bool), critical (bool). ``write_dir`` receives the moved config (needed only
    with a namespace).
    """
    nsp = ns.namespace if namespace is None else namespace
    procs = ns.processes(layout)
    composed = any(p.composed for p in procs)
    if (nsp.strip('/') or composed) and write_dir is None:
        raise NodeSetError('launch_entries: a namespace or a composed layout needs write_dir '
                           '(the moved site config, the composed nodes\' overrides files)')
    config, params = site_config(config, nsp, write_dir or '.', ns)
    out = []
    for proc in procs:
        if proc.composed:
            args = {}
            for node in proc.nodes:
                overrides = node_overrides(ns, node, params, use_sim_time=use_sim_time, namespace=nsp)
                ofile = Path(write_dir) / f'{node.name}.params.yaml'
                ofile.write_text(yaml.safe_dump(overrides_document(ns, node, overrides, nsp)))
                args[node.name] = ros_args(ns, node, config, overrides_file=ofile, namespace=nsp)
            out.append({'package': COMPOSED[0], 'executable': COMPOSED[1], 'name': None, 'process': proc.name,
                        'nodes': [n.name for n in proc.nodes], 'arguments': composed_args(proc, args),
                        'namespace': nsp, 'parameters': [], 'remappings': [], 'lifecycle': False,
                        'critical': any(n.critical for n in proc.nodes)})
            continue
        node = proc.nodes[0]
        overrides = node_overrides(ns, node, params, use_sim_time=use_sim_time, namespace=nsp)
        out.append({'package': node.package, 'executable': node.executable, 'name': node.name,
                    'process': node.name, 'nodes': [node.name], 'arguments': [],
                    'namespace': nsp, 'parameters': [str(config), overrides] if overrides else [str(config)],
                    'remappings': list(remaps(node, nsp).items()), 'lifecycle': node.lifecycle,
                    'critical': node.critical})
    return out


def sim_board_argv(board: BoardSpec, exe_path: str | os.PathLike, values: Mapping[str, Any]) -> list[str]:
    """Command line of ``board``'s simulator with ``{placeholders}`` filled from ``values``."""
    if not board.sim_executable:
        raise NodeSetError(f'board {board.name!r} has no simulator')
    try:
        return [str(exe_path), *(a.format(**values) for a in board.sim_args)]
    except KeyError as exc:
        raise NodeSetError(f'board {board.name!r}: unknown placeholder {exc} in sim args') from exc


def ros_environment(ns: NodeSet, base: Mapping[str, str] | None = None,
                    domain_id: int | None = None, *, namespace: str = '',
                    run_dir: str | os.PathLike | None = None) -> dict[str, str]:
    """Environment for the node processes: the node set's domain and discovery range
    unless the caller's environment (or ``domain_id``) sets them. With
    ``ROS_DISCOVERY_SERVER`` (a collector of a field, docs/field.md) no discovery range
    is added: the discovery servers decide who is found. The node set's Fast DDS
    profile (config/fastdds_profile.xml: a 7.5 s participant lease, see
    :mod:`sslfr_bringup.dds_profile`) unless the environment names its own; for a
    collector of a field (a discovery client in ``namespace``) that profile plus ROS's
    graph topic in the collector's own partition, written to ``run_dir``
    (:func:`sslfr_bringup.dds_profile.with_graph_partition`): the collectors do not
    learn each other's nodes."""
    env = dict(os.environ if base is None else base)
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(domain_id)
    else:
        env.setdefault('ROS_DOMAIN_ID', str(ns.domain_id))
    if not env.get('ROS_DISCOVERY_SERVER'):
        env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', ns.discovery_range)
    env.setdefault('PYTHONUNBUFFERED', '1')
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    env = with_profile(env, config_dir())
    nsp = (namespace or '').strip('/')
    if nsp and field_client(env) and run_dir is not None:
        env = with_graph_partition(env, nsp, run_dir)
    return env
