"""``ros2 launch sslfr_bringup tracker.launch.py [config:=FILE] [namespace:=/ns]
[domain_id:=N] [discovery_range:=LOCALHOST|SUBNET|OFF|SYSTEM_DEFAULT] [use_sim_time:=true]
[layout:=composed|separate]``

The whole tracker on a Pi with ROS 2 Jazzy from apt. A THIN reader of the one node-set
description (config/nodeset.yaml via :mod:`sslfr_bringup.nodeset`); `./sslfr up` reads
the same description and applies it the same way:

- discovery is contained as in `./sslfr up`: ROS_DOMAIN_ID and
  ROS_AUTOMATIC_DISCOVERY_RANGE are the node set's (domain 42, LOCALHOST: nothing
  leaves the Pi) unless set in the environment or given as launch arguments; a
  collector of a field (``ROS_DISCOVERY_SERVER`` in the environment) gets its own
  discovery server on 127.0.0.1 as with `./sslfr up` (sslfr_bringup.local_discovery);
- under ``namespace:=/ns`` the site config's node sections are moved with the nodes
  (rcl matches a bare ``planner:`` section only in the root namespace), so several
  collectors, each with its own config, share one domain;
- ``layout:=`` chooses the processes (default: the node set's, ``separate``: a process
  per node; ``composed``: the drivers and sensor nodes in one ``composed`` process,
  planner, web and recorder in another, safety alone: the choice for a Pi);
- ``use_sim_time:=true`` reaches every node (replaying a day with ``ros2 bag play --clock``);
- the axis drivers (lifecycle nodes) activate themselves, also after a respawn and when
  their board appears late; launch only starts them (an outside lifecycle command is
  still obeyed and not undone).

- executor liveness: launch restarts a process only when it exits, so one more process
  of the launch, ``liveness_watchdog`` (sslfr_bringup/watchdog.py), binds a
  ``NOTIFY_SOCKET`` in the launch's run directory; every node process gets that socket
  and ``WATCHDOG_USEC`` (the node set's ``watchdog_timeout``) in its environment and
  beats ``WATCHDOG=1`` from its spin loop; a process whose beats stop for longer is
  SIGKILLed by the watchdog and respawned by launch (``respawn=True``), the cause
  printed on the launch's output (the run directory is removed when the launch stops).
  A node process is respawned no sooner than its DDS
  participant lease + 1 s after its death (``respawn_delay``; 8.5 s with the node set's
  Fast DDS profile, config/fastdds_profile.xml; :mod:`sslfr_bringup.dds_profile` says why).

The supervisor of `./sslfr up` adds what launch does not do: restart with backoff and
an ordered stop (axes first); the systemd unit uses `sslfr up` for that reason
(docs/deploy.md).
"""


def _entries(config: str | None = None, namespace: str | None = None, write_dir: str | None = None,
             use_sim_time: bool = False, layout: str | None = None) -> list[dict]:
    """Process entries to launch (pure: no `launch` import, tested without ROS launch)."""
    from sslfr_bringup import nodeset

    ns = nodeset.load()
    cfg = nodeset.resolve_config(config or None, default=ns.config)
    ns = nodeset.for_config(ns, cfg, namespace)       # the nodes the collector's description names
    return nodeset.launch_entries(ns, cfg, namespace=namespace, write_dir=write_dir,
                                  use_sim_time=use_sim_time, layout=layout)


def _liveness(write_dir: str) -> tuple[list[str], dict[str, str]]:
    """The watchdog's arguments and the environment every node process gets (pure)."""
    import os

    from sslfr_bringup import nodeset

    ns = nodeset.load()
    sock = os.path.join(write_dir, 'notify.sock')
    return (['--socket', sock, '--timeout', f'{ns.watchdog_timeout:g}'],
            {'NOTIFY_SOCKET': sock, 'WATCHDOG_USEC': str(int(ns.watchdog_timeout * 1e6))})


def _environment(domain_id: str, discovery_range: str, namespace: str = '',
                 write_dir: str | None = None) -> dict[str, str]:
    """ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE for the nodes: the launch arguments
    when given, else the environment's, else the node set's (as `sslfr up`); the Fast
    DDS profile (FASTRTPS_DEFAULT_PROFILES_FILE: the node set's unless the environment
    names one; a collector of a field in ``namespace``: with its graph partition, written
    to ``write_dir``, as nodeset.ros_environment says)."""
    import os

    from sslfr_bringup import dds_profile, nodeset

    ns = nodeset.load()
    base = {}
    if domain_id:
        base['ROS_DOMAIN_ID'] = domain_id
    if discovery_range:
        base['ROS_AUTOMATIC_DISCOVERY_RANGE'] = discovery_range
    env = nodeset.ros_environment(ns, base={**os.environ, **base}, namespace=namespace, run_dir=write_dir)
    return {k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DISCOVERY_SERVER',
                                dds_profile.PROFILE_ENV) if k in env}


def _respawn_delay(env: dict[str, str]) -> float:
    """[s] A node process's respawn delay: 2 s, and never less than the wait after its
    death that its DDS participant lease asks for (sslfr_bringup.dds_profile)."""
    from sslfr_bringup import dds_profile

    return max(2.0, dds_profile.restart_wait(env))


def generate_launch_description():
    from launch import LaunchDescription
    from launch.actions import (DeclareLaunchArgument, ExecuteProcess, LogInfo, OpaqueFunction, RegisterEventHandler,
                                SetEnvironmentVariable)
    from launch.event_handlers import OnShutdown
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import LifecycleNode, Node

    def _setup(context):
        import os
        import tempfile

        def arg(name):
            return LaunchConfiguration(name).perform(context)
        namespace = arg('namespace')
        use_sim_time = arg('use_sim_time').lower() in ('true', '1', 'yes')
        import shutil
        write_dir = tempfile.mkdtemp(prefix='sslfr-launch-')    # moved config, composed nodes' overrides
        env = _environment(arg('domain_id'), arg('discovery_range'), namespace, write_dir)
        # a collector of a field: its own discovery server first (sslfr_bringup.local_discovery)
        from sslfr_bringup import local_discovery
        server, servers, note = local_discovery.local_server({**os.environ, **env})
        if servers:
            env['ROS_DISCOVERY_SERVER'] = servers
        actions = [SetEnvironmentVariable(k, v) for k, v in env.items()]
        if note:
            actions.append(LogInfo(msg=note))
        if server:
            actions.append(ExecuteProcess(cmd=server, name=local_discovery.PROGRAM, output='screen',
                                          respawn=True, respawn_delay=1.0))
        # the run directory goes with the launch (its files are read at a process's start)
        actions.append(RegisterEventHandler(OnShutdown(
            on_shutdown=lambda event, context: shutil.rmtree(write_dir, ignore_errors=True))))
        respawn_delay = _respawn_delay(env)
        watchdog_args, notify_env = _liveness(write_dir)
        actions.append(Node(package='sslfr_bringup', executable='liveness_watchdog', arguments=watchdog_args,
                            output='screen', respawn=True, respawn_delay=1.0))
        for e in _entries(arg('config'), namespace or None, write_dir, use_sim_time, arg('layout') or None):
            if e['name'] is None:          # a composed process: each node's own --ros-args in arguments
                actions.append(Node(package=e['package'], executable=e['executable'], arguments=e['arguments'],
                                    output='screen', respawn=True, respawn_delay=respawn_delay,
                                    additional_env=notify_env))
                continue
            common = dict(package=e['package'], executable=e['executable'], name=e['name'],
                          namespace=e['namespace'], parameters=e['parameters'],
                          remappings=e['remappings'], output='screen',
                          respawn=True, respawn_delay=respawn_delay, additional_env=notify_env)
            actions.append(LifecycleNode(**common) if e['lifecycle'] else Node(**common))
        return actions

    return LaunchDescription([
        DeclareLaunchArgument('config', default_value='',
                              description='site params file (path or name in sslfr_bringup/config); '
                                          'default: the node set\'s (almeria_sslfr.yaml)'),
        DeclareLaunchArgument('namespace', default_value='', description='namespace of the whole tracker'),
        DeclareLaunchArgument('layout', default_value='',
                              description='process layout (config/nodeset.yaml layouts: composed = drivers and '
                                          'sensors in one process, safety alone; separate = a process per node; '
                                          'default: the node set\'s)'),
        DeclareLaunchArgument('domain_id', default_value='',
                              description='ROS_DOMAIN_ID of the nodes (default: $ROS_DOMAIN_ID, else the '
                                          'node set\'s, 42)'),
        DeclareLaunchArgument('discovery_range', default_value='',
                              description='ROS_AUTOMATIC_DISCOVERY_RANGE (default: the environment\'s, '
                                          'else the node set\'s, LOCALHOST)'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='true: every node takes ROS time from /clock (ros2 bag play --clock)'),
        OpaqueFunction(function=_setup),
    ])
