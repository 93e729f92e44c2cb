"""Shared pytest fixtures for the SSLFR tracker.

Topic-level tests start the real node executables as processes (as ``ros2 run``
would: ``ros_ws/install/<pkg>/lib/<pkg>/<exe>``) and talk to them from an rclpy
node in the test process. Every test gets its own ``ROS_DOMAIN_ID`` (held with a
file lock, so concurrent pytest runs on one machine never share a domain) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``.

Fixtures
--------
ros_domain   int, the test's private domain id
ros_env      dict, environment for node processes (domain, log dir, discovery range)
launch       factory: ``launch(pkg, exe, *ros_args, params={...}, name=None)`` ->
             :class:`NodeProcess` (stopped with SIGINT at teardown)
ros          a :class:`RosHarness`: an rclpy context + node in the test's domain with
             ``spin_until(predicate, timeout)``, ``collect(type, topic)``, ``call(...)``
"""
from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT / 'tests'))   # the harness and the shared test helpers

from harness import NodeProcess, RosHarness, acquire_test_domain, executable  # noqa: E402,F401 - re-exported to tests


@pytest.fixture
def ros_domain():
    dom, fh = acquire_test_domain()
    yield dom
    fh.close()                  # releases the lock


@pytest.fixture
def ros_env(ros_domain, tmp_path):
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(ros_domain)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_LOG_DIR'] = str(tmp_path / 'roslog')
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    return env


#: the firmware-in-the-loop files that run a whole node set on several firmware boards
#: (about one core each): one after another on one worker, beside the single-board files
FIRMWARE_NODE_SETS = ('test_fw_system.py', 'test_fw_prototypes.py')


def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` (make test, scripts/test.sh): one test file per worker at a time,
    as xdist's own, but the firmware node-set files are one unit (one after another on
    one worker). xdist's ``loadgroup`` would do it with marks but does not group on
    pytest 9.2 (pytest-dev/pytest-xdist#1386)."""
    if config.getvalue('dist') != 'loadfile':
        return None
    from collections import OrderedDict

    from xdist.scheduler import LoadFileScheduling
    node_sets = 'firmware-node-sets'

    class NodeSetsFirst(OrderedDict):
        """The work queue: the node-set unit first (xdist orders units by their number of
        tests; its four long tests would start last, the other worker then idle)."""
        def __setitem__(self, key, value):
            super().__setitem__(key, value)
            if key == node_sets:
                self.move_to_end(key, last=False)

    class FileScheduling(LoadFileScheduling):
        def __init__(self, config, log=None):
            super().__init__(config, log)
            self.workqueue = NodeSetsFirst()

        def _split_scope(self, nodeid: str) -> str:
            if Path(nodeid.split('::', 1)[0]).name in FIRMWARE_NODE_SETS:
                return node_sets
            return super()._split_scope(nodeid)
    return FileScheduling(config, log)


_LAUNCHED = pytest.StashKey[list]()
_LOG_TAIL = 3000          # characters of each node's output put in a failed test's report


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """A test that fails while nodes it launched run gets the tail of each node's own
    output in its report (the processes and their temporary logs are gone after)."""
    report = yield
    if report.when == 'call' and report.failed:
        for proc in item.stash.get(_LAUNCHED, []):
            report.sections.append((f'node output: {proc.log_path.stem} (last {_LOG_TAIL} chars)',
                                    proc.output()[-_LOG_TAIL:]))
    return report


@pytest.fixture
def launch(request, ros_env, tmp_path):
    """Start node executables; all are stopped at teardown."""
    procs: list[NodeProcess] = []
    request.node.stash[_LAUNCHED] = procs

    def _launch(package: str, exe: str, *args: str, params: dict | None = None,
                name: str | None = None, env: dict | None = None,
                ros_args: list[str] | None = None) -> NodeProcess:
        path = executable(package, exe)
        if not path.exists():
            pytest.fail(f'{path} is not installed: run make setup')
        argv = [str(path), *args]
        extra = list(ros_args or [])
        for key, value in (params or {}).items():
            if isinstance(value, bool):
                value = 'true' if value else 'false'
            elif isinstance(value, (list, tuple)):
                value = '[' + ','.join(repr(v) if isinstance(v, str) else str(v) for v in value) + ']'
            extra += ['-p', f'{key}:={value}']
        if name:
            extra += ['-r', f'__node:={name}']
        if extra:
            argv += ['--ros-args', *extra]
        log = tmp_path / f'{name or exe}-{len(procs)}.log'
        proc = NodeProcess(argv, {**ros_env, **(env or {})}, log)
        procs.append(proc)
        return proc

    yield _launch
    for proc in reversed(procs):
        proc.stop()
        if os.environ.get('SSLFR_TEST_SHOW_LOGS'):
            sys.stderr.write(f'--- {proc.argv[0]}\n{proc.output()}\n')


@pytest.fixture
def ros(ros_domain):
    harness = RosHarness(ros_domain)
    yield harness
    harness.close()


# ----------------------------------------------------------------- leak check
# Every test owns the processes, ptys and temporary directories it starts, and leaves
# none behind. pytest makes itself a child subreaper (Linux prctl), so a grandchild
# orphaned by its parent (a node started by `sslfr sim`, a simulator whose runner died)
# is re-parented to pytest and is still seen here. After each test: descendants that
# outlive it are reported by name and killed, and the test errors.
_LEAK_GRACE_S = 5.0        # stop() gives a node 5 s after SIGINT; a leak outlives that
_TMP_PATTERNS = ('sslfr-sim-*', 'axd*', 'sslfr-up-*')


def _become_subreaper() -> None:
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(36, 1, 0, 0, 0)            # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):         # not Linux: orphans go to init, unseen
        pass


_become_subreaper()

# pytest started in the background by a non-interactive shell (`make soak &` in a
# script) inherits SIGINT ignored, and so would every process a test starts, which
# changes what Ctrl-C does to them (Python then raises no KeyboardInterrupt). The tests
# see what a terminal gives; test_replay_ctrl_c_stops_cleanly[ignored] covers the other.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# A private temporary directory per pytest run (inherited by every child through
# TMPDIR), so the check below sees only what this run's tests left, never the files
# of another run on the same machine. Short: UNIX socket paths must stay < 108 bytes.
_RUN_TMP = tempfile.mkdtemp(prefix=f'sslfr-t{os.getpid()}-')
os.environ['TMPDIR'] = _RUN_TMP
tempfile.tempdir = _RUN_TMP


def pytest_unconfigure(config):
    shutil.rmtree(_RUN_TMP, ignore_errors=True)


def _descendants() -> dict[int, str]:
    import psutil
    out = {}
    for p in psutil.Process().children(recursive=True):
        try:
            if p.status() == psutil.STATUS_ZOMBIE:
                p.wait(0)                       # reap what the subreaper inherited
                continue
            out[p.pid] = ' '.join(p.cmdline()[:4]) or p.name()
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.TimeoutExpired):
            pass
    return out


def _pty_fds() -> set[str]:
    out = set()
    for fd in os.listdir('/proc/self/fd'):
        try:
            target = os.readlink(f'/proc/self/fd/{fd}')
        except OSError:
            continue
        if target.startswith('/dev/pts/') or target == '/dev/ptmx':
            out.add(f'fd {fd} -> {target}')
    return out


def _tmp_dirs() -> set[str]:
    import glob
    return {p for pat in _TMP_PATTERNS for p in glob.glob(os.path.join(_RUN_TMP, pat))}


@pytest.fixture(autouse=True)
def _no_leaks(request):
    """Fail a test that leaves a process, a pty or an sslfr temp dir behind."""
    before_procs, before_ptys, before_tmp = set(_descendants()), _pty_fds(), _tmp_dirs()
    yield
    import psutil
    deadline = time.monotonic() + _LEAK_GRACE_S
    leaked = {}
    while True:
        leaked = {pid: cmd for pid, cmd in _descendants().items() if pid not in before_procs}
        if not leaked or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    for pid in leaked:                       # clean up so the next test starts clean
        try:
            psutil.Process(pid).kill()
        except psutil.NoSuchProcess:
            pass
    problems = [f'process {pid} still running: {cmd}' for pid, cmd in sorted(leaked.items())]
    problems += [f'pty left open: {p}' for p in sorted(_pty_fds() - before_ptys)]
    tmp_left = sorted(_tmp_dirs() - before_tmp)
    problems += [f'temporary directory left behind: {p}' for p in tmp_left]
    for path in tmp_left:
        shutil.rmtree(path, ignore_errors=True)
    if problems:
        pytest.fail(f'{request.node.nodeid} leaked:\n  ' + '\n  '.join(problems), pytrace=False)
