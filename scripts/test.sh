#!/usr/bin/env bash
# `make test`: the whole suite, every test once (no reruns), in three parts.
#
#  1. the unit tests (src/*/test: pure modules, numbers and bytes, a few single nodes),
#     in the background, output kept and printed after part 2;
#  2. meanwhile the topic-level tests (tests/ without test_fw_*): node sets on DDS and
#     simulated boards on ptys. The unit tests occupy about one core while they run,
#     which is the load `make soak BUSY=1` shows these tests keep their deadlines under;
#  3. then, alone, the firmware-in-the-loop tests (tests/test_fw_*: the real firmware in
#     simavr uses both cores).
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

UNITS=(src/sslfr_interfaces/test src/sslfr_planner/test src/sslfr_drivers/test src/sslfr_bringup/test)
FIRMWARE=(tests/test_fw_*.py)
log="$(mktemp "${TMPDIR:-/tmp}/sslfr-units.XXXXXX")"
trap 'rm -f "$log"' EXIT

t0=$SECONDS
python -m pytest "${UNITS[@]}" "$@" >"$log" 2>&1 &
units_pid=$!

echo "== make test: topic-level tests (tests/), the unit tests (src/) running alongside"
python -m pytest tests --ignore-glob='tests/test_fw_*' "$@"
topic_rc=$?
t_topic=$((SECONDS - t0))

wait "$units_pid"
units_rc=$?
echo
echo "== make test: unit tests (src/*/test), run alongside the topic-level tests"
cat "$log"
t_host=$((SECONDS - t0))

echo
echo "== make test: firmware-in-the-loop tests (tests/test_fw_*), alone"
python -m pytest "${FIRMWARE[@]}" "$@"
fw_rc=$?
t_fw=$((SECONDS - t0 - t_host))

verdict() { [ "$1" = 0 ] && echo passed || echo "FAILED (exit $1)"; }
echo
echo "== make test: topic-level $(verdict $topic_rc) (${t_topic} s), unit $(verdict $units_rc)," \
     "host tests ${t_host} s in all; firmware-in-the-loop $(verdict $fw_rc) (${t_fw} s)"
[ "$topic_rc" = 0 ] && [ "$units_rc" = 0 ] && [ "$fw_rc" = 0 ]
