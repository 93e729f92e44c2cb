#!/usr/bin/env bash
# `make test`: the whole suite, every test once (no reruns), in two parts.
#
#  1. the host tests: the topic-level tests (tests/ without test_fw_*: node sets on DDS
#     and simulated boards on ptys) and the unit tests (src/*/test: pure modules,
#     numbers and bytes, a few single nodes), spread over two pytest-xdist workers, one
#     test file per worker at a time (--dist loadfile: a module's fixtures run once).
#     Each test owns its ROS domain, temporary directories and ptys, so two run side by
#     side; most topic-level tests wait on simulated time at a fixed speed, not on CPU
#     (load average ~2-2.6 on this 2-core machine). `make soak` runs the topic-level
#     tests the same way (and with one core busy: BUSY=1);
#  2. then, apart from them, the firmware-in-the-loop tests (tests/test_fw_*: the real
#     firmware in simavr, paced at real time) on two workers: the files that run a whole
#     node set on firmware boards (about a core each) one after another on one worker
#     (conftest.py FIRMWARE_NODE_SETS, its xdist scheduler), the single-board files
#     (little CPU, waiting on
#     the AVRs' real time) on the other.
#
# Arguments (make test PYTEST_ARGS=...) are passed to every part. When they name a test
# path (a file, a directory, file::test), that selection runs as one plain pytest instead.
# Exit status: 0 when every part passed.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# shellcheck disable=SC1091
. scripts/env.sh

for a in "$@"; do
  if [ -e "${a%%::*}" ] && [ "${a#-}" = "$a" ]; then
    exec python -m pytest "$@"
  fi
done

HOST=(tests --ignore-glob='tests/test_fw_*'
      src/sslfr_common/test src/sslfr_planner/test src/sslfr_drivers/test src/sslfr_safety/test
      src/sslfr_bringup/test src/sslfr_recording/test src/sslfr_web/test src/sslfr_gateway/test src/sslfr_field/test src/sslfr_sim/test)
FIRMWARE=(tests/test_fw_*.py)
WORKERS="${SSLFR_TEST_WORKERS:-2}"

t0=$SECONDS
echo "== make test: host tests (tests/ topic-level and src/*/test units), $WORKERS workers"
python -m pytest -n "$WORKERS" --dist loadfile --durations=25 "${HOST[@]}" "$@"
host_rc=$?
t_host=$((SECONDS - t0))

echo
echo "== make test: firmware-in-the-loop tests (tests/test_fw_*), $WORKERS workers (node sets on one)"
python -m pytest -n "$WORKERS" --dist loadfile --durations=10 "${FIRMWARE[@]}" "$@"
fw_rc=$?
t_fw=$((SECONDS - t0 - t_host))

verdict() { [ "$1" = 0 ] && echo passed || echo "FAILED (exit $1)"; }
echo
echo "== make test: host tests $(verdict $host_rc) (${t_host} s); firmware-in-the-loop $(verdict $fw_rc) (${t_fw} s)"
[ "$host_rc" = 0 ] && [ "$fw_rc" = 0 ]
