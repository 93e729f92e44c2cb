"""The operator page in a real browser: Debian's headless chromium driven by selenium
(chromedriver from Debian too; nothing downloaded) against the whole node set of
``./sslfr sim`` (simulated boards, simulated day at 30x from before sunrise).

The browser loads the page, sees the phase change (NIGHT -> PRE_DAWN -> TRACKING) and the
measured angles change, is refused a command without login, logs in with the operator
password, presses Stow and sees the planner's phase become STOW, then switches to
maintenance and jogs the mirrors by -0.5 deg through the driver (a 30 deg jog is refused). A screenshot of the
page is kept as an artifact: out/test-artifacts/web-operator-page.png (and -phone.png at a
phone's 390 px width, where nothing may be wider than the screen; paths printed).
Page load time and the state-to-page delay are printed (docs/measurements.md).

Set-up installs chromium + chromium-driver when root on Debian (scripts/setup-browser.sh);
without them this test skips with the command to run, and fails under CI=true.
"""
from __future__ import annotations

import contextlib
import os
import re
import time
from pathlib import Path

import pytest

from conftest import ROOT, NodeProcess

from sslfr_web import auth

CHROMIUM, CHROMEDRIVER = Path('/usr/bin/chromium'), Path('/usr/bin/chromedriver')
PASSWORD = 'browser-test-pass'
ARTIFACTS = ROOT / 'out' / 'test-artifacts'
# Chromium flags for a headless run on a machine without network (python.md):
# background networking off, or it keeps trying to reach Google's hosts.
FLAGS = ('--headless=new', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--disable-dev-shm-usage', '--window-size=1280,2200')


def _require_browser():
    missing = [str(p) for p in (CHROMIUM, CHROMEDRIVER) if not p.exists()]
    if missing:
        why = (f'{" and ".join(missing)} missing: make setup installs them as root on Debian, '
               f'else run: apt-get install chromium chromium-driver')
        if os.environ.get('CI') == 'true':
            pytest.fail(why)
        pytest.skip(why)


@pytest.fixture
def browser(tmp_path):
    _require_browser()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for flag in FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f'--user-data-dir={tmp_path / "chromium-profile"}')
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER), log_output=str(tmp_path / 'chromedriver.log')),
                              options=opts)
    driver.set_script_timeout(20)
    yield driver
    driver.quit()


@contextlib.contextmanager
def _sim(ros_env, tmp_path, *args: str):
    """`./sslfr sim` with ``args`` (window, config); yields (page url, tmp_path)."""
    _require_browser()
    pw = auth.write_password_file(tmp_path / 'pw', PASSWORD)
    out = tmp_path / 'sim'
    cmd = [str(ROOT / 'sslfr'), 'sim', *args, '--no-report', '--out', str(out),
           '--set', f'web:password_file={pw}', '--set', f'web:audit_file={tmp_path / "audit.jsonl"}',
           '--set', f'web:report_dir={tmp_path / "reports"}']
    proc = NodeProcess(cmd, ros_env, tmp_path / 'sim.out')       # own session; SIGINT then SIGKILL at the end
    url = None
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.running() and url is None:
        weblog = out / 'logs' / 'web.log'
        m = re.search(r'operator page at (http://\S+/)', weblog.read_text(errors='replace')) if weblog.exists() else None
        url = m.group(1) if m else None
        time.sleep(0.2)
    try:
        assert url, proc.output()[-3000:]
        yield url, tmp_path
    finally:
        proc.stop(timeout=30)


@pytest.fixture
def sim(ros_env, tmp_path):
    """`./sslfr sim` from 04:30 UTC at 30x (PRE_DAWN 04:40:45, TRACKING 04:50:45 at Almeria:
    21 s and 41 s of wall time after the simulated clock starts)."""
    with _sim(ros_env, tmp_path, '--date', '2026-06-21', '--start', '04:30', '--end', '05:40', '--speed', '30') as s:
        yield s


def _wait(driver, predicate, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    pytest.fail(f'{what} not seen within {timeout} s; page shows phase '
                f'{driver.find_element("id", "phase-name").text!r}')


def test_operator_page_in_chromium_against_the_simulated_tracker(browser, sim):
    # (the browser starts first: the page is open before the simulated clock runs)
    url, tmp = sim
    text = lambda i: browser.find_element('id', i).text  # noqa: E731
    t0 = time.monotonic()
    browser.get(url)
    load_ms = browser.execute_script(
        "const n = performance.getEntriesByType('navigation')[0]; return n.loadEventEnd - n.startTime;")
    _wait(browser, lambda: browser.execute_script('return window.sslfrLog.length > 0'), 60, 'a first live state')
    first_state_ms = browser.execute_script('return window.sslfrLog[0].at - performance.timeOrigin')
    print(f'page load {load_ms:.0f} ms (navigation to load event), first live state at {first_state_ms:.0f} ms '
          f'after navigation start')
    assert load_ms < 20000          # generous: 0.5 s on a quiet machine, 7.7 s once at load average 35

    # the phase and the measured angles change, live
    # the tracker starts stowed until every driver and the absorber board have spoken
    # (issue 21): the first phase to judge is the one after that start-up STOW
    phase0 = _wait(browser, lambda: text('phase-name') not in ('', '…', 'STOW') and text('phase-name'), 60, 'a phase')
    angle0 = _wait(browser, lambda: text('axis-mirrors-measured') not in ('', '–') and text('axis-mirrors-measured'),
                   60, 'the mirrors angle')
    assert phase0 in ('NIGHT', 'PRE_DAWN'), f'the page showed {phase0} first: loaded too late to see a change'
    _wait(browser, lambda: text('phase-name') not in (phase0,) and text('phase-name') in ('PRE_DAWN', 'TRACKING'),
          90, f'a phase change from {phase0}')
    _wait(browser, lambda: text('axis-mirrors-measured') != angle0, 60, 'the mirrors angle changing')
    assert browser.find_element('id', 'conn').text == 'live'
    assert browser.find_elements('css selector', '#view-south line.mirror'), 'no mirrors drawn'
    # state -> page: the browser's arrival time minus the node's snapshot time (same machine clock)
    lags = browser.execute_script(
        'return window.sslfrLog.slice(-20).map(e => e.at - e.server_time * 1000)')
    print(f'snapshot -> page over {len(lags)} events: median {sorted(lags)[len(lags) // 2]:.0f} ms, '
          f'max {max(lags):.0f} ms')
    assert sorted(lags)[len(lags) // 2] < 1000      # the 1 s goal, publication -> page: tests/test_web_node.py

    # without login: the buttons are disabled and the API refuses
    assert not browser.find_element('id', 'cmd-stow').is_enabled()
    refused = browser.execute_async_script("""
        const done = arguments[arguments.length - 1];
        fetch('/api/command/stow', {method: 'POST', headers: {'Content-Type': 'application/json'}, body: '{}'})
          .then(r => r.json().then(j => done([r.status, j.message])));""")
    assert refused[0] == 401 and 'log in' in refused[1]
    assert 'software stop' in text('estop-notice') and 'not' in text('estop-notice')

    # log in, press Stow: the planner's phase becomes STOW
    browser.find_element('id', 'login-password').send_keys(PASSWORD)
    browser.find_element('id', 'login-btn').click()
    _wait(browser, lambda: 'Logged in' in text('login-state'), 20, 'the login')
    _wait(browser, lambda: browser.find_element('id', 'cmd-stow').is_enabled(), 10, 'the Stow button enabled')
    browser.find_element('id', 'cmd-stow').click()
    _wait(browser, lambda: 'done' in text('cmd-log'), 15, "the stow service's answer")
    _wait(browser, lambda: text('phase-name') == 'STOW', 15, 'phase STOW')
    assert text('mode') == 'mode stow'
    time.sleep(1.0)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / 'web-operator-page.png'
    assert browser.save_screenshot(str(shot)) and shot.stat().st_size > 10000
    print(f'screenshot: {shot}')
    # the day plots come from the node's buffer: a reload shows them again
    n = _wait(browser, lambda: browser.execute_script('return page.history && page.history.t.length'), 30,
              'day-plot samples')
    browser.refresh()
    # right after the reload `page.history` is null until the page has fetched it
    _wait(browser, lambda: (browser.execute_script('return page.history && page.history.t.length') or 0) >= n, 30,
          'the day plots after a reload')
    assert browser.find_elements('css selector', '#plot-angles path'), 'no angle curves after the reload'
    _wait(browser, lambda: text('phase-name') == 'STOW', 15, 'phase STOW after the reload')

    # maintenance, then jog the mirrors through the driver's own service (and beyond the limit: refused)
    browser.find_element('id', 'cmd-mode-maintenance').click()
    _wait(browser, lambda: text('phase-name') == 'MAINTENANCE', 15, 'phase MAINTENANCE')
    measured = lambda: browser.execute_script('return page.last.axes.mirrors.measured')  # noqa: E731
    time.sleep(1.0)
    before = measured()
    jog = browser.find_element('id', 'jog-deg')
    jog.clear()
    jog.send_keys('0.5')
    browser.find_element('id', 'jog-minus').click()          # stowed mirrors sit at the upper limit (+90 deg)
    _wait(browser, lambda: 'jog mirrors −0.5' in text('cmd-log'), 15, "the jog's answer")
    first = browser.find_element('css selector', '#cmd-log li').text
    assert 'done' in first and 'jogging' in first, first
    _wait(browser, lambda: abs(measured() - before + 0.5 * 3.14159265 / 180) < 0.002, 20, 'the mirrors jogged 0.5 deg')
    jog.clear()
    jog.send_keys('30')
    browser.find_element('id', 'jog-minus').click()
    _wait(browser, lambda: 'jog mirrors −30' in text('cmd-log'), 15, 'the refusal')
    first = browser.find_element('css selector', '#cmd-log li').text
    assert 'REFUSED' in first and 'beyond the jog limit' in first, first

    # a phone screen (390 x 844 CSS px): one column, nothing wider than the screen
    browser.set_window_size(390, 844)
    time.sleep(1.0)
    width = browser.execute_script('return [document.documentElement.scrollWidth, window.innerWidth]')
    assert width[0] <= width[1] + 1, f'page {width[0]} px wide on a {width[1]} px screen'
    for wide in ('card-axes', 'card-commands', 'card-drawing'):
        box = browser.find_element('id', wide).rect
        assert box['x'] >= 0 and box['x'] + box['width'] <= width[1] + 1, (wide, box)
    phone = ARTIFACTS / 'web-operator-page-phone.png'
    browser.save_screenshot(str(phone))
    print(f'screenshot (phone): {phone}')
    audit = (tmp / 'audit.jsonl').read_text()
    assert '"command": "stow"' in audit and '127.0.0.1' in audit
    print(f'browser test took {time.monotonic() - t0:.0f} s after the page address was known')


def test_operator_page_draws_the_described_collector(browser, ros_env, tmp_path):
    """Seed 004's site config (its collector description: one movement, ten lines): the
    page lists and jogs the mirrors only, draws ten lines at the measured drive plus
    Table 1's offsets, and the rows and receiver fixed in the side view. Screenshot:
    out/test-artifacts/web-operator-page-lepten.png."""
    import math
    with _sim(ros_env, tmp_path, '--config', 'florianopolis_lepten.yaml', '--date', '2026-06-21',
              '--start', '15:00', '--end', '15:20', '--speed', '30') as (url, _):
        browser.get(url)
        _wait(browser, lambda: browser.execute_script(
            'return !!(page.last && page.last.info.collector && page.last.axes && page.last.axes.mirrors)'),
            60, "the collector's description and the mirrors' status")
        time.sleep(1.0)       # one more render with both
        # read in one script turn: the drawings are redrawn at every live state
        got = browser.execute_script("""
            const q = (sel) => Array.from(document.querySelectorAll(sel));
            const name = document.getElementById('south-name');
            return {rows: q('#axes tbody tr').map((r) => r.id), jog: q('#jog-axis option').map((o) => o.textContent),
                    angles: q('#view-south line.mirror').map((l) => parseFloat(l.getAttribute('data-angle'))),
                    drive: page.last.axes.mirrors.measured, fixed: !!document.getElementById('side-structure-fixed'),
                    tilting: !!document.getElementById('side-structure'), name: name ? name.textContent : ''};""")
        assert got['rows'] == ['axis-mirrors'] and got['jog'] == ['mirrors'], got
        assert len(got['angles']) == 10, got
        b1 = math.radians(15.8311)                  # Table 1's b of line 1 (east end)
        assert abs(got['angles'][0] - got['drive'] - b1) < 0.01, got   # the drawing may be one state behind
        assert got['fixed'] and not got['tilting'] and got['name'] == 'florianopolis_lepten', got
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        shot = ARTIFACTS / 'web-operator-page-lepten.png'
        assert browser.save_screenshot(str(shot))
        print(f'screenshot: {shot}')
