#!/usr/bin/env bash
# Part of `make setup` (called by scripts/setup.sh): Debian's chromium and chromedriver
# for the operator page's real-browser test (tests/test_web_browser.py, selenium).
# Root on Debian: installed with apt-get. Otherwise the exact command is printed and
# the browser test skips with that reason; with CI=true a missing browser is an error.
set -euo pipefail
say() { printf 'setup: %s\n' "$*"; }
have() { [ -x /usr/bin/chromium ] && [ -x /usr/bin/chromedriver ]; }
have && exit 0
CMD="apt-get install -y chromium chromium-driver"
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && grep -qs '^ID=debian' /etc/os-release; then
  say "installing Debian's chromium and chromium-driver (the operator page's browser test)"
  LOG="$(mktemp /tmp/sslfr-apt-browser.XXXXXX.log)"
  if DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >"$LOG" 2>&1 \
     || { apt-get update -q >>"$LOG" 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver >>"$LOG" 2>&1; }; then
    rm -f "$LOG"
    have && exit 0
  fi
  tail -5 "$LOG" >&2
  MSG="could not install chromium + chromium-driver (log: $LOG)"
else
  MSG="the operator page's browser test needs Debian's chromium: run as root: $CMD"
fi
if [ "${CI:-}" = true ]; then
  printf 'setup: ERROR: %s\n' "$MSG" >&2
  exit 1
fi
say "$MSG (tests/test_web_browser.py skips until then)"
