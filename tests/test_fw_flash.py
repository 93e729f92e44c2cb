"""``sslfr flash`` end to end, without hardware: simavr runs the bootloader Debian's
arduino-core-avr ships for the Pro Mini 16 MHz (ATmegaBOOT_168_atmega328.hex, 57600
bit/s) on a pty with an empty application flash; avrdude (through ``sslfr flash``)
writes our firmware into it; the board restarts into the firmware, answers INFO, and
takes its EEPROM configuration. Plus what the bootloader means for the watchdog."""
from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import ROOT
from fw_support import RawHost, fw_host, provisioned, require  # noqa: F401

from sslfr_drivers.link import messages as m

pytestmark = pytest.mark.timeout(240)


@pytest.fixture(scope='module', autouse=True)
def _built():
    require('firmware', 'sim')
    from sslfr_drivers import firmware as fw
    problem = fw.toolchain_problem('flash')
    if problem:
        import os
        if os.environ.get('CI', '').lower() in ('1', 'true', 'yes'):
            pytest.fail(problem)
        pytest.skip(problem)


def test_sslfr_flash_through_the_debian_bootloader(tmp_path):
    from sslfr_drivers import firmware as fw
    from sslfr_sim.fw_harness import Harness, axis_mech
    h = Harness('axis', bootloader=str(fw.BOOTLOADER), app=False, link=str(tmp_path / 'promini'),
                mech=axis_mech('mirrors')).start()
    try:
        assert h.status()['pc'] >= 0x7800 * 1, 'running the bootloader'
        proc = subprocess.run([str(ROOT / 'sslfr'), 'flash', 'axis', '--port', str(tmp_path / 'promini'),
                               '--set', 'axis=secondary_reflector', '--set', 'board_id=0x2A', '--set', 'max_speed=2500'],
                              capture_output=True, text=True, timeout=200)
        print(proc.stdout, proc.stderr[-2000:])
        assert proc.returncode == 0, proc.stderr
        assert 'bytes of flash verified' in proc.stdout
        assert 'board: sslfr-axis firmware 1.0.0 protocol 2 id 0' in proc.stdout
        assert 'config: ConfigRecord(layout=1, kind=1, board_id=42, baud=115200, axis=2, flags=0, ' \
               'max_speed=2500.0' in proc.stdout
        host = fw_host(h.path, key=None)          # freshly flashed: not provisioned
        info = host.request(m.GetInfo())
        assert (info.name_str, info.firmware, info.board_id) == ('sslfr-axis', '1.0.0', 42)
        host.close()
    finally:
        h.stop()


def test_flash_refuses_a_bad_configuration_before_writing(tmp_path):
    proc = subprocess.run([str(ROOT / 'sslfr'), 'flash', 'axis', '--port', '/dev/null', '--set', 'speed=3'],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and 'KEY one of' in proc.stderr


@pytest.mark.parametrize('bootloader,comes_back', [('atmega/ATmegaBOOT_168_atmega328.hex', False),
                                                   ('optiboot/optiboot_atmega328.hex', True)])
def test_watchdog_reset_needs_a_watchdog_aware_bootloader(tmp_path, bootloader, comes_back):
    """A watchdog reset (RESET request, hung firmware) restarts the chip in its
    bootloader with the watchdog still running at 16 ms. The Pro Mini's stock
    ATmegaBOOT does not stop it: the board resets every 16 ms inside the bootloader and
    never reaches the firmware (as on real boards, until a power cycle). Optiboot (also
    shipped by arduino-core-avr) starts the application at once: BOOT, not HOMED."""
    from sslfr_drivers import firmware as fw
    from sslfr_sim.fw_harness import Harness, axis_mech
    h = Harness('axis', bootloader=str(fw.ARDUINO / 'bootloaders' / bootloader), app=True,
                link=str(tmp_path / 'b'), mech=axis_mech('mirrors')).start()
    host = fw_host(h.path, key=None)              # a blank EEPROM: not provisioned
    try:
        info = None                 # the firmware runs after power-up (after the bootloader's wait)
        for _ in range(10):
            if host.hello(timeout=0.5) is None:
                continue
            info = host.answer(host.send(m.GetInfo()), timeout=0.5)
            if info is not None:
                break
        assert info is not None and info.name_str == 'sslfr-axis'
        assert host.request(m.SetZero(15000)) == m.Ack(m.SetZero.TYPE)
        h.cmd('hang')
        frames = host.poll(2.5)
        st = h.status()
        assert st['watchdog_resets'] >= 1
        if comes_back:
            assert any(f.type == m.Boot.TYPE for f in frames)
            assert st['watchdog_resets'] == 1 and not host.request(m.GetStatus()).homed
        else:
            assert not frames and st['watchdog_resets'] > 20 and st['pc'] >= 0x7800, st
    finally:
        host.close()
        h.stop()
