"""``ros2 launch sslfr_bringup tracker.launch.py [config:=FILE] [namespace:=/ns]``

The whole tracker on a Pi with ROS 2 Jazzy from apt. A THIN reader of the one node-set
description (config/nodeset.yaml via :mod:`sslfr_bringup.nodeset`); `./sslfr up` reads
the same description. Lifecycle nodes (the axis drivers) are configured, then
activated, as soon as they start. The supervisor of `./sslfr up` adds what launch
does not do: restart with backoff and an ordered stop (axes first); the systemd unit
uses `sslfr up` for that reason (docs/deploy.md).
"""


def _entries(config: str | None = None, namespace: str | None = None) -> list[dict]:
    """Node entries to launch (pure: no `launch` import, tested without ROS launch)."""
    from sslfr_bringup import nodeset

    ns = nodeset.load()
    cfg = nodeset.resolve_config(config or None, default=ns.config)
    return nodeset.launch_entries(ns, cfg, namespace=namespace)


def generate_launch_description():
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
    from launch.events import matches_action
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import LifecycleNode, Node
    from launch_ros.event_handlers import OnStateTransition
    from launch_ros.events.lifecycle import ChangeState
    from lifecycle_msgs.msg import Transition

    def _setup(context):
        config = LaunchConfiguration('config').perform(context)
        namespace = LaunchConfiguration('namespace').perform(context)
        actions = []
        for e in _entries(config, namespace or None):
            common = dict(package=e['package'], executable=e['executable'], name=e['name'],
                          namespace=e['namespace'], parameters=e['parameters'],
                          remappings=e['remappings'], output='screen',
                          respawn=True, respawn_delay=2.0)
            if not e['lifecycle']:
                actions.append(Node(**common))
                continue
            node = LifecycleNode(**common)
            actions.append(RegisterEventHandler(OnStateTransition(
                target_lifecycle_node=node, goal_state='inactive',
                entities=[EmitEvent(event=ChangeState(
                    lifecycle_node_matcher=matches_action(node),
                    transition_id=Transition.TRANSITION_ACTIVATE))])))
            actions.append(node)
            actions.append(EmitEvent(event=ChangeState(
                lifecycle_node_matcher=matches_action(node),
                transition_id=Transition.TRANSITION_CONFIGURE)))
        return actions

    return LaunchDescription([
        DeclareLaunchArgument('config', default_value='',
                              description='site params file (path or name in sslfr_bringup/config); '
                                          'default: the node set\'s (almeria_sslfr.yaml)'),
        DeclareLaunchArgument('namespace', default_value='', description='namespace of the whole tracker'),
        OpaqueFunction(function=_setup),
    ])
