"""``composed``: several nodes of the tracker in one process, one executor, one DDS
participant (ROS 2 composition in Python; the ``composed`` layout of config/nodeset.yaml).

    composed --process NAME --node module:Class --ros-args -r __node:=mirrors_driver \
        --params-file site.yaml --params-file mirrors_driver.params.yaml --node ...

Each ``--node`` names its node class (``component:`` in the node set) and its own
``--ros-args`` (name, namespace, params files, remaps): the node is built with
``cli_args`` = those arguments and ``use_global_arguments=False``, so each node has its
own name and parameters exactly as it would in its own process. The life of the
process is :func:`sslfr_common.node.run_nodes` (signals, ``on_exit`` of each node in
order, exit 2 naming a node that refuses its configuration) with one single-threaded
executor (``sslfr_common.executor.LeanExecutor``): no node of the tracker waits in a callback (the axis drivers do
their board I/O in their own threads). The Python loggers of every class's
``LOG_BRIDGE`` reach the first node's logger.
`sslfr up`, `sslfr sim` and tracker.launch.py build this command line
(:func:`sslfr_bringup.nodeset.composed_args`).
"""
from __future__ import annotations

import importlib
import sys

from sslfr_planner.cli_input import OneLineParser


def split_nodes(argv: list[str]) -> tuple[str, list[tuple[str, list[str]]]]:
    """``(process name, [(module:Class, ros args), ...])`` from the command line
    (without the program name); ValueError with the reason when it is not one."""
    if len(argv) < 2 or argv[0] != '--process':
        raise ValueError('usage: composed --process NAME --node module:Class --ros-args ... [--node ...]')
    name, rest = argv[1], argv[2:]
    nodes: list[tuple[str, list[str]]] = []
    for arg in rest:
        if arg == '--node':
            nodes.append(('', []))
        elif not nodes:
            raise ValueError(f'expected --node, got {arg!r}')
        elif not nodes[-1][0]:
            nodes[-1] = (arg, [])
        else:
            nodes[-1][1].append(arg)
    if not nodes or any(not c or ':' not in c for c, _ in nodes):
        raise ValueError('every --node needs module:Class')
    return name, nodes


def node_class(component: str):
    """The class named ``module:Class``."""
    module, _, attr = component.partition(':')
    return getattr(importlib.import_module(module), attr)


def _node_name(ros_args: list[str], default: str) -> str:
    return next((a.split(':=', 1)[1] for a in ros_args if a.startswith('__node:=')), default)


def main(argv: list[str] | None = None) -> int:
    from sslfr_common.node import run_nodes

    argv = sys.argv[1:] if argv is None else argv
    try:
        process, specs = split_nodes(argv)
        classes = [node_class(c) for c, _ in specs]
    except (ValueError, ImportError, AttributeError) as exc:
        OneLineParser(prog='composed').error(str(exc))
    bridge = tuple(dict.fromkeys(name for c in classes for name in getattr(c, 'LOG_BRIDGE', ())))

    def maker(cls, ros_args):
        return lambda: cls(cli_args=list(ros_args), use_global_arguments=False)

    nodes = [(_node_name(a, c.split(':')[1]), maker(cls, a)) for (c, a), cls in zip(specs, classes)]
    return run_nodes(nodes, args=[f'composed:{process}'], log_bridge=bridge)


if __name__ == '__main__':
    raise SystemExit(main())
