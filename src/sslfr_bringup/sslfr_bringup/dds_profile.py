"""The Fast DDS profile of the node processes and the restart wait it implies (pure).

A node process that dies without leaving the graph (the supervisor's SIGKILL of a
hung process, a crash) stays known to the other processes until its participant
lease runs out; until then they keep writing to its shared-memory port. A process
restarted during that time takes the same port and may end up listening on a port
segment that some publishers no longer write to: it never hears them (Fast DDS
2.14, reproduced with the recorder and the safety node; docs/deploy.md "Restart after
a hang"). So a node process is restarted no sooner than the lease (+ a margin) after
its death. The node set's profile (config/fastdds_profile.xml) shortens the lease
from Fast DDS's 20 s to 7.5 s (announced every 3 s, as Fast DDS does) so that this
wait stays short.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Mapping

#: the environment variable Fast DDS 2.x (ROS 2 Jazzy) reads its default profile from
PROFILE_ENV = 'FASTRTPS_DEFAULT_PROFILES_FILE'
#: file name of the node set's profile in sslfr_bringup's config directory
PROFILE_FILE = 'fastdds_profile.xml'
#: [s] Fast DDS's participant lease when a profile does not set one
FASTDDS_DEFAULT_LEASE = 20.0
#: [s] added to the lease: the others' lease timers and a supervision pass
RESTART_MARGIN = 1.0

_NS = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'


class ProfileError(ValueError):
    """The profile file cannot be read or its lease is not a duration."""


def _local(tag: str) -> str:
    return tag.rsplit('}', 1)[-1]


def _child(elem: ET.Element, name: str) -> ET.Element | None:
    return next((c for c in elem if _local(c.tag) == name), None)


def _duration(elem: ET.Element) -> float:
    """A Fast DDS duration element (<sec>, <nanosec>) in seconds; DURATION_INFINITY
    (or an absent <sec>) is infinite."""
    sec, nsec = _child(elem, 'sec'), _child(elem, 'nanosec')
    text = (sec.text or '').strip() if sec is not None else ''
    if not text or text.upper() == 'DURATION_INFINITY':
        return float('inf')
    try:
        value = float(text) + (float((nsec.text or '0').strip()) * 1e-9 if nsec is not None else 0.0)
    except ValueError:
        raise ProfileError(f'lease duration is not a number: {text!r}') from None
    if value <= 0:
        raise ProfileError(f'lease duration must be positive, got {value:g} s')
    return value


def participant_lease(path: str | os.PathLike | None) -> float:
    """The participant lease [s] that the default participant profile of the Fast DDS
    XML file ``path`` gives (``is_default_profile="true"``, else the only participant
    profile); Fast DDS's 20 s when there is no file or it sets none."""
    if not path:
        return FASTDDS_DEFAULT_LEASE
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ProfileError(f'cannot read the Fast DDS profile {path}: {exc}') from None
    profiles = [e for e in root.iter() if _local(e.tag) == 'participant']
    chosen = [p for p in profiles if p.get('is_default_profile', '').lower() == 'true']
    if not chosen and len(profiles) == 1:
        chosen = profiles
    if not chosen:
        return FASTDDS_DEFAULT_LEASE
    lease = next((e for e in chosen[0].iter() if _local(e.tag) == 'leaseDuration'), None)
    return _duration(lease) if lease is not None else FASTDDS_DEFAULT_LEASE


def restart_wait(env: Mapping[str, str]) -> float:
    """[s] The shortest time from a node process's death to its restart for the
    profile the environment ``env`` gives the node processes: its lease + margin."""
    lease = participant_lease(env.get(PROFILE_ENV))
    if lease == float('inf'):
        raise ProfileError(f'{env.get(PROFILE_ENV)}: an infinite participant lease: a dead node process '
                           'would never be forgotten by the others, so it could never be restarted safely')
    return lease + RESTART_MARGIN


def with_profile(env: dict[str, str], config_dir: Path) -> dict[str, str]:
    """``env`` with the node set's profile (``config_dir/PROFILE_FILE``) unless it
    already names a profile (the operator's own)."""
    if not env.get(PROFILE_ENV):
        env[PROFILE_ENV] = str(config_dir / PROFILE_FILE)
    return env


#: ROS 2's graph topic (rmw_fastrtps): every participant publishes and reads its nodes on it
GRAPH_TOPIC = 'ros_discovery_info'
#: the partition of the station's processes: every collector's (a Fast DDS wildcard)
ALL_PARTITIONS = '*'
#: file name of the profile :func:`with_graph_partition` writes into a run directory
FIELD_PROFILE_FILE = 'fastdds_field_profile.xml'
#: the graph partition in force (set with the profile by :func:`with_graph_partition`)
PARTITION_ENV = 'SSLFR_GRAPH_PARTITION'


def graph_partition_profile(base: str | os.PathLike | None, partition: str, out: str | os.PathLike) -> Path:
    """Write to ``out`` the profile ``base`` (none: an empty one) with the graph topic's
    writer and reader in ``partition``, and return ``out``.

    In a field every participant reads :data:`GRAPH_TOPIC`, so without partitions each
    collector learns every other collector's nodes through the discovery servers.
    rmw_fastrtps takes a writer's and a reader's QoS from the profile named after the
    topic; ROS's QoS settings leave the partition alone. A collector's processes share
    its own partition; the station's use :data:`ALL_PARTITIONS` and see everyone.
    Profiles of that name already in ``base`` are replaced."""
    if base:
        try:
            tree = ET.parse(base)
        except (OSError, ET.ParseError) as exc:
            raise ProfileError(f'cannot read the Fast DDS profile {base}: {exc}') from None
        root = tree.getroot()
    else:
        root = ET.Element(f'{_NS}profiles')
        tree = ET.ElementTree(root)
    holder = root if _local(root.tag) == 'profiles' else next(
        (e for e in root.iter() if _local(e.tag) == 'profiles'), None)
    if holder is None:
        raise ProfileError(f'{base}: no <profiles> element')
    ns = holder.tag[:-len('profiles')]          # the profiles' XML namespace, '' when none
    for kind in ('data_writer', 'data_reader'):
        for old in [e for e in holder if _local(e.tag) == kind and e.get('profile_name') == GRAPH_TOPIC]:
            holder.remove(old)
        prof = ET.SubElement(holder, f'{ns}{kind}', profile_name=GRAPH_TOPIC)
        names = ET.SubElement(ET.SubElement(ET.SubElement(prof, f'{ns}qos'), f'{ns}partition'), f'{ns}names')
        ET.SubElement(names, f'{ns}name').text = partition
    ET.register_namespace('', _NS[1:-1])
    tree.write(out, encoding='unicode', xml_declaration=True)
    return Path(out)


def with_graph_partition(env: dict[str, str], partition: str, run_dir: str | os.PathLike) -> dict[str, str]:
    """``env`` whose profile (its own or none) puts the graph topic in ``partition``:
    the combined profile is written to ``run_dir`` (:func:`graph_partition_profile`)."""
    out = Path(run_dir) / FIELD_PROFILE_FILE
    env[PROFILE_ENV] = str(graph_partition_profile(env.get(PROFILE_ENV) or None, partition, out))
    env[PARTITION_ENV] = partition
    return env


def adopt_graph_partition(env: Mapping[str, str]) -> None:
    """Give this process's own ROS participant (the supervisor's ROS side, which waits
    for the nodes in the graph) the profile of ``env`` when that profile has a graph
    partition: in another partition it would never see its own nodes. Call it before
    the process's first participant (Fast DDS reads the profile then)."""
    if env.get(PARTITION_ENV):
        os.environ[PROFILE_ENV] = env[PROFILE_ENV]
        os.environ[PARTITION_ENV] = env[PARTITION_ENV]
