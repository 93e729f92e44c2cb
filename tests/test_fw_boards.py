"""The boards' exact firmware (.elf) in simavr, one board at a time, against the
requirements of docs/protocol.md and docs/firmware.md: sizes, BOOT, every NACK code,
the trapezoidal step generation, limit switches stopping motion in the interrupt, the
1 s host-silence watchdog, the AVR hardware watchdog, the EEPROM configuration
procedure, the sensor boards' chips (MAX6675, VEML7700 auto-ranging, NEO-6 NMEA) and
the UART bridge losing no byte. Real time (the harness is paced 1:1)."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from fw_support import KEY, RawHost, fw_host, provisioned, require  # noqa: F401

from sslfr_drivers.link import messages as m
from sslfr_drivers.link import sensor_messages as ms

pytestmark = pytest.mark.timeout(120)
STEP = math.radians(0.006)


@pytest.fixture(scope='module', autouse=True)
def _built():
    require('firmware', 'sim')


def _harness(board, tmp, record=None, **kw):
    """The board's harness. Paced at half real time unless a test needs real time: on a
    loaded machine the test process may stall for a moment, which must not look like a
    silent host to the firmware (the timing assertions use simulated time)."""
    from sslfr_sim.fw_board import config_record
    from sslfr_sim.fw_harness import Harness, axis_mech
    kw.setdefault('pace', 0.5 if board == 'axis' else 1.0)
    if board == 'axis':
        kw.setdefault('mech', axis_mech('mirrors'))
    rec = record or config_record(board, {'axis': 'mirrors'}, 7)
    return Harness(board, eeprom=provisioned(rec), link=str(tmp / board), **kw).start()


@pytest.fixture
def axis(tmp_path):
    h = _harness('axis', tmp_path)
    host = fw_host(h.path).heartbeat()
    yield h, host
    host.close()
    h.stop()


def test_sizes_within_the_pro_mini():
    """flash <= 30 KB (32 KB minus the 2 KB bootloader), static RAM <= 1.5 KB."""
    from sslfr_drivers import firmware as fw
    for board in fw.BOARDS:
        out = subprocess.run(['avr-size', '-A', str(fw.elf(board))], capture_output=True, text=True,
                             check=True).stdout
        sec = {ln.split()[0]: int(ln.split()[1]) for ln in out.splitlines() if ln.startswith('.')}
        flash = sec.get('.text', 0) + sec.get('.data', 0)
        ram = sec.get('.data', 0) + sec.get('.bss', 0) + sec.get('.noinit', 0)
        print(f'{board}: flash {flash} B, static RAM {ram} B')
        assert flash <= 30 * 1024, (board, flash)
        assert ram <= 1536, (board, ram)


def test_boot_info_and_not_homed(axis):
    h, host = axis
    boot = []
    for _ in range(30):
        boot += [f for f in host.poll(0.1) if f.type == m.Boot.TYPE]
        if boot:
            break
    assert boot and boot[0].seq == 0 and m.decode(boot[0]) == m.Boot(m.BoardKind.AXIS_STEPPER, 2)
    info = host.request(m.GetInfo())
    assert (info.board_kind, info.firmware, info.protocol, info.board_id, info.name_str) == \
        (1, '1.0.0', 2, 7, 'sslfr-axis')
    st = host.request(m.GetStatus())
    assert not st.homed and st.fault_bits & m.FaultBits.RESET and math.isnan(st.sensor_angle)
    assert st.limit_bits == m.LimitBits.HIGH | m.LimitBits.SLEEP      # the mirrors rest at +90 deg


def test_every_nack_code(axis):
    h, host = axis
    E = m.ErrorCode
    assert host.request(m.MoveTo(100, 1000)) == m.Nack(m.MoveTo.TYPE, E.NOT_HOMED)
    assert host.request(None, mtype=0x42, payload=b'') == m.Nack(0x42, E.UNKNOWN_TYPE)
    assert host.request(None, mtype=m.MoveTo.TYPE, payload=b'\x01\x02') == m.Nack(m.MoveTo.TYPE, E.BAD_PAYLOAD)
    assert host.request(None, mtype=m.Ping.TYPE, payload=b'') == m.Nack(m.Ping.TYPE, E.BAD_PAYLOAD)
    import struct
    nan = struct.pack('<if', 5, math.nan)
    assert host.request(None, mtype=m.MoveTo.TYPE, payload=nan) == m.Nack(m.MoveTo.TYPE, E.BAD_PAYLOAD)
    assert host.request(m.Ping(1), version=1) == m.Nack(m.Ping.TYPE, E.VERSION)
    assert host.request(m.SetZero(15000)) == m.Ack(m.SetZero.TYPE)
    assert host.request(m.MoveTo(100, 0.0)) == m.Nack(m.MoveTo.TYPE, E.OUT_OF_RANGE)
    assert host.request(m.MoveTo(2**30 + 1, 10.0)) == m.Nack(m.MoveTo.TYPE, E.OUT_OF_RANGE)
    assert host.request(m.Home(3, 100.0, 0)) == m.Nack(m.Home.TYPE, E.OUT_OF_RANGE)
    # on the HIGH switch (+90 deg): further up is refused, down is fine
    assert host.request(m.MoveTo(15100, 1000)) == m.Nack(m.MoveTo.TYPE, E.LIMIT_ACTIVE)
    h.cmd('driver_fault 1')
    assert host.request(m.MoveTo(14000, 1000)) == m.Nack(m.MoveTo.TYPE, E.FAULT_ACTIVE)
    assert host.request(m.GetStatus()).fault_bits & m.FaultBits.DRIVER
    h.cmd('driver_fault 0')
    assert host.request(m.Home(m.Switch.LOW, -3000.0, -7500)) == m.Ack(m.Home.TYPE)
    assert host.request(m.MoveTo(14000, 1000)) == m.Nack(m.MoveTo.TYPE, E.BUSY)
    assert host.request(m.SetConfig(m.ConfigRecord.defaults(1).pack())) == m.Nack(m.SetConfig.TYPE, E.BUSY)
    bad = m.ConfigRecord.defaults(1)
    import dataclasses
    assert host.request(m.SetConfig(dataclasses.replace(bad, max_speed=1e6).pack())) == \
        m.Nack(m.SetConfig.TYPE, E.OUT_OF_RANGE)
    assert host.request(m.Stop()) == m.Ack(m.Stop.TYPE)
    # ERR_INTERNAL (EEPROM verify failure after SET_CONFIG) cannot be provoked in simavr


def test_duplicate_answered_from_cache_and_stale_ignored(axis):
    h, host = axis
    host.stop_heartbeat()            # the retry must follow its request directly
    host.request(m.SetZero(15000))
    seq = host.send(m.MoveTo(14000, 500))
    first = host.answer(seq)
    time.sleep(0.2)
    pos1 = h.status()['counter']
    host.send(m.MoveTo(14000, 500), seq=seq)            # a retry: same seq, same type
    again = host.answer(seq)
    assert first == again == m.Ack(m.MoveTo.TYPE)
    assert h.status()['requests_duplicate'] == 1
    stale = host.send(m.Stop(), seq=seq - 5)
    # refused REPLAY, not executed: still moving (a restarted host opens a new session)
    assert host.answer(stale, timeout=0.5) == m.Nack(m.Stop.TYPE, m.ErrorCode.REPLAY)
    assert h.status()['counter'] < pos1 and h.status()['requests_stale'] == 1


def _profile(h, seconds, period=0.02):
    out = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        st = h.status()
        out.append((st['sim_time'], st['model_steps'], st['speed']))
        time.sleep(period)
    return out


def test_trapezoidal_profile_at_20000_steps_per_s(tmp_path):
    """Top speed reached and held, ramps at the EEPROM acceleration, stop exactly on
    the target (no overshoot); >= 2000 steps/s required, 20 000 configured."""
    from sslfr_sim.fw_board import config_record
    rec = config_record('axis', {'axis': 'mirrors', 'max_speed': 20000, 'accel': 40000}, 1)
    h = _harness('axis', tmp_path, rec)
    host = fw_host(h.path).heartbeat()
    try:
        host.request(m.SetZero(0))
        assert host.request(m.MoveTo(-16000, 30000.0)) == m.Ack(m.MoveTo.TYPE)
        prof = _profile(h, 1.6)
        st = h.wait(lambda s: s['speed'] == 0.0, 6)
        assert st['counter'] == -16000 and st['model_steps'] == -16000 and st['target'] == -16000
        # the joint never went past the target
        assert min(p[1] for p in prof) >= -16000
        rates = [(b[1] - a[1]) / (b[0] - a[0]) for a, b in zip(prof, prof[1:]) if b[0] > a[0]]
        assert min(rates) >= -20000 * 1.05, min(rates)              # never above top speed
        cruise = [r for r in rates if r < -19000]
        assert len(cruise) >= 5, rates                                # top speed held
        # ramp: 0 -> 20000 steps/s at 40000 steps/s^2 takes 0.5 s
        t_start = next(p[0] for p in prof if p[1] != 0)
        t_top = next(p[0] for p in prof if p[2] <= -19999)
        assert 0.4 < t_top - t_start < 0.6, t_top - t_start
    finally:
        host.close()
        h.stop()


def test_limit_switch_stops_the_motor_at_the_switch(axis):
    """A move past the LOW end (mirrors -45 deg) is stopped by the switch inside the step
    interrupt: joint at the switch within one step, fault LIMIT, further moves down refused."""
    h, host = axis
    host.request(m.SetZero(15000))                       # 90 deg
    assert host.request(m.MoveTo(-9000, 3000)) == m.Ack(m.MoveTo.TYPE)   # -54 deg: beyond the switch
    st = h.wait(lambda s: s['speed'] == 0.0 and s['counter'] < 0, 40)
    lo = math.radians(-45)
    assert lo - STEP <= st['angle'] <= lo + 1e-9, math.degrees(st['angle'])
    assert st['faults'] & m.FaultBits.LIMIT and st['limit_bits'] & 1
    status = host.request(m.GetStatus())
    assert status.limit_bits & m.LimitBits.LOW and status.fault_bits & m.FaultBits.LIMIT
    assert status.position == st['counter'] and abs(status.position * STEP + 0 - (st['angle'] - math.pi / 2 + 15000 * STEP)) < 1e-6
    assert host.request(m.MoveTo(-9000, 3000)) == m.Nack(m.MoveTo.TYPE, m.ErrorCode.LIMIT_ACTIVE)
    assert host.request(m.MoveTo(0, 3000)) == m.Ack(m.MoveTo.TYPE)          # away: allowed


def test_home_on_the_sleep_switch(axis):
    h, host = axis
    host.request(m.SetZero(0))
    h.cmd(f'set_angle {math.radians(80)}')
    assert host.request(m.Home(m.Switch.SLEEP, 3000.0, 15000)) == m.Ack(m.Home.TYPE)
    st = h.wait(lambda s: s['homed'] and not s['homing'] and s['speed'] == 0, 10)
    status = host.request(m.GetStatus())
    assert status.homed and not status.homing and not status.fault_bits & m.FaultBits.RESET
    # the counter is `position` where the switch closed (0.1 deg below its centre)
    edge = math.pi / 2 - math.radians(0.1)
    assert abs(st['angle'] - edge) <= STEP and abs(status.position - 15000) <= 1


HOST_SCRIPT = r'''
import sys, time
from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink
from sslfr_drivers.link.transport import SerialTransport
link = BoardLink(SerialTransport(sys.argv[1]), heartbeat=0.25, key=bytes.fromhex(sys.argv[2])).start()
assert link.wait_up(5)
link.request(m.SetZero(0))
link.request(m.MoveTo(-1000000, 3000.0))
print('moving', flush=True)
while True:
    link.request(m.GetStatus())
    time.sleep(0.1)
'''


def test_host_killed_motor_stopped_within_1_2_s(tmp_path):
    """The host process dies (SIGKILL) while the axis moves at 3000 steps/s: the 1 s
    host-silence watchdog decelerates the motor to a stop; last step <= 1.2 s after the
    last byte received (simulated time), fault WATCHDOG latched."""
    from sslfr_sim.fw_board import config_record
    from sslfr_sim.fw_harness import axis_mech
    rec = config_record('axis', {'axis': 'mobile_structure'}, 1)
    h = _harness('axis', tmp_path, rec, mech=axis_mech('mobile_structure', 0.0), pace=1.0)
    proc = subprocess.Popen([sys.executable, '-c', HOST_SCRIPT, h.path, KEY.hex()], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == 'moving'
        time.sleep(1.0)
        assert h.status()['speed'] != 0
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(5)
        st = h.wait(lambda s: s['speed'] == 0.0 and s['sim_time'] - s['last_step_s'] > 0.3, 5)
        stopped_after = st['last_step_s'] - st['last_rx_s']
        print(f'last byte -> motor stopped: {stopped_after:.3f} s (simulated)')
        assert 1.0 <= stopped_after <= 1.2, stopped_after
        assert st['faults'] & m.FaultBits.WATCHDOG and st['watchdog_trips'] == 1
    finally:
        if proc.poll() is None:
            proc.kill()
        h.stop()


STOW_HOST_SCRIPT = r'''
import sys, time
from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink
from sslfr_drivers.link.transport import SerialTransport
link = BoardLink(SerialTransport(sys.argv[1]), heartbeat=0.25, key=bytes.fromhex(sys.argv[2])).start()
assert link.wait_up(5)
link.request(m.SetZero(0))
assert isinstance(link.request(m.SetHostLossStow(m.HostLossMode.POSITION, 0, 14000, 3000.0, 2000)), m.Ack)
link.request(m.MoveTo(-2000, 3000.0))
while link.request(m.GetStatus()).moving:
    time.sleep(0.05)
print('ready', flush=True)
while True:
    link.request(m.GetStatus())
    time.sleep(0.1)
'''


def test_host_killed_axis_drives_to_its_host_loss_stow_by_itself(tmp_path):
    """Issue 35: the host dies; the board stops (watchdog, 1 s), waits the stored delay
    (2 s) and drives to its host-loss stow (14000 steps = 84 deg, 16000 steps away at
    3000 steps/s: ~5.8 s of travel) by itself; a host that comes back reads fault
    HOST_LOSS, a PING does not move it, a MOVE_TO does."""
    from sslfr_sim.fw_board import config_record
    from sslfr_sim.fw_harness import axis_mech
    rec = config_record('axis', {'axis': 'mirrors'}, 1)
    h = _harness('axis', tmp_path, rec, mech=axis_mech('mirrors', 0.0), pace=1.0)
    proc = subprocess.Popen([sys.executable, '-c', STOW_HOST_SCRIPT, h.path, KEY.hex()], stdout=subprocess.PIPE,
                            text=True)
    host = None
    try:
        assert proc.stdout.readline().strip() == 'ready'
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(5)
        st = h.wait(lambda s: s['counter'] == 14000 and s['speed'] == 0.0, 20)
        travel = 16000 / 3000.0 + 3000.0 / 6000.0          # cruise + one ramp (accel 6000 steps/s^2)
        took = st['last_step_s'] - st['last_rx_s']
        print(f'last byte -> host-loss stow reached: {took:.2f} s (simulated; bound 1 + 2 + {travel:.2f} s)')
        assert 3.0 + travel - 0.5 <= took <= 3.0 + travel + 0.3, took
        assert abs(st['angle'] - math.radians(84.0)) <= 2 * STEP
        assert st['faults'] & m.FaultBits.HOST_LOSS and not st['faults'] & m.FaultBits.LIMIT
        host = fw_host(h.path)
        status = host.request(m.GetStatus())
        assert status.fault_bits & m.FaultBits.HOST_LOSS and status.position == 14000 and not status.moving
        assert not status.flags & m.StatusFlags.HOST_LOSS_STOWING
        time.sleep(0.5)
        assert h.status()['counter'] == 14000                   # the host's PING/STATUS: no motion
        assert host.request(m.MoveTo(13000, 3000.0)) == m.Ack(m.MoveTo.TYPE)
        assert not host.request(m.GetStatus()).fault_bits & m.FaultBits.HOST_LOSS
        # a stow record the configuration cannot run is refused
        nack = host.request(m.SetHostLossStow(m.HostLossMode.SWITCH, 3, 0, 3000.0, 2000))
        assert nack == m.Nack(m.SetHostLossStow.TYPE, m.ErrorCode.OUT_OF_RANGE)
    finally:
        if host is not None:
            host.close()
        if proc.poll() is None:
            proc.kill()
        h.stop()


def test_host_loss_stow_toward_a_switch_and_kept_in_eeprom(tmp_path):
    """SWITCH mode works without a reference: toward the SLEEP switch until it closes
    (no LIMIT fault); the record survives a reset (EEPROM)."""
    h = _harness('axis', tmp_path)
    host = fw_host(h.path)
    try:
        assert host.request(m.SetHostLossStow(m.HostLossMode.SWITCH, m.Switch.SLEEP, 0, 3000.0, 1000)) == \
            m.Ack(m.SetHostLossStow.TYPE)
        h.cmd(f'set_angle {math.radians(80)}')
        boots = h.status()['boot_count']
        assert host.request(m.Reset()) == m.Ack(m.Reset.TYPE)      # not homed after the reset
        host.close()
        h.wait(lambda s: s['boot_count'] > boots, 5)
        host = fw_host(h.path)
        assert host.request(m.Ping(0)) == m.Ack(m.Ping.TYPE)       # then silent
        st = h.wait(lambda s: s['speed'] == 0.0 and s['limit_bits'] & m.LimitBits.SLEEP and not s['hl_stowing'],
                    20)
        assert abs(st['angle'] - (math.pi / 2 - math.radians(0.1))) <= 2 * STEP     # the switch's edge
        assert st['faults'] & m.FaultBits.HOST_LOSS and not st['faults'] & m.FaultBits.LIMIT and not st['homed']
    finally:
        host.close()
        h.stop()


def test_hung_firmware_reset_by_the_avr_watchdog(axis):
    """The firmware hangs with interrupts off: the AVR watchdog (0.5 s) resets it; the
    board sends BOOT and is not HOMED (position lost, fault RESET)."""
    h, host = axis
    host.request(m.SetZero(15000))
    assert host.request(m.GetStatus()).homed
    host.poll(0.1)
    t0 = h.status()['sim_time']
    h.cmd('hang')
    boot = []
    deadline = time.monotonic() + 3
    while not boot and time.monotonic() < deadline:
        boot = [f for f in host.poll(0.05) if f.type == m.Boot.TYPE]
    st = h.status()
    assert boot and boot[0].seq == 0, 'BOOT after the watchdog reset'
    assert st['watchdog_resets'] == 1 and st['resets'] == 1
    status = host.request(m.GetStatus())
    assert not status.homed and status.fault_bits & m.FaultBits.RESET
    assert 0.4 < st['sim_time'] - t0 < 1.5


def test_reset_request_reboots_with_boot(axis):
    """RESET: ACK, then the firmware restarts (a software restart from the reset vector,
    not the watchdog: see test_fw_flash) and sends BOOT; the position is lost."""
    h, host = axis
    host.request(m.SetZero(15000))
    n = len(host.received)
    assert host.request(m.Reset()) == m.Ack(m.Reset.TYPE)
    host.poll(0.5)
    boot = [f for f in host.received[n:] if f.type == m.Boot.TYPE]
    assert boot and boot[0].seq == 0
    st = host.request(m.GetStatus())
    assert not st.homed and st.fault_bits & m.FaultBits.RESET and st.uptime_ms < 600


def test_eeprom_configuration_procedure(axis):
    """SET_CONFIG stores the record (ACK), it takes effect after RESET: GET_CONFIG and
    INFO show it, the new top speed holds; it survives a power cycle."""
    import dataclasses
    h, host = axis
    rec = dataclasses.replace(host.request(m.GetConfig()).value, board_id=0xC0FFEE, axis=1, max_speed=1500.0,
                              min_steps=-20000, max_steps=20000)
    assert host.request(m.SetConfig(rec.pack())) == m.Ack(m.SetConfig.TYPE)
    assert host.request(m.GetInfo()).board_id == 7                  # not yet in use
    host.request(m.Reset())
    host.poll(0.3)
    assert host.request(m.GetConfig()).value == rec
    assert host.request(m.GetInfo()).board_id == 0xC0FFEE
    host.request(m.SetZero(15000))
    assert host.request(m.MoveTo(20001, 10.0)) == m.Nack(m.MoveTo.TYPE, m.ErrorCode.OUT_OF_RANGE)
    host.request(m.MoveTo(5000, 20000.0))
    time.sleep(1.5)
    assert abs(host.request(m.GetStatus()).speed) == pytest.approx(1500.0)
    h.cmd('reset')                                                     # power cycle
    host.poll(0.3)
    assert host.request(m.GetConfig()).value == rec


def test_position_sensor_as5048a(tmp_path):
    """With the optional encoder configured the STATUS sensor angle follows the joint to
    the encoder's resolution (2 pi / 16384)."""
    from sslfr_sim.fw_board import config_record
    rec = config_record('axis', {'axis': 'mirrors', 'sensor': 1}, 1)
    h = _harness('axis', tmp_path, rec, sensor_zero=rec.sensor_zero)
    host = fw_host(h.path)
    try:
        for deg in (90.0, 12.345, -30.0):
            h.cmd(f'set_angle {math.radians(deg)}')
            time.sleep(0.05)
            st = host.request(m.GetStatus())
            assert st.flags & m.StatusFlags.HAS_SENSOR
            assert abs(st.sensor_angle - math.radians(deg)) <= 2 * math.pi / 16384, (deg, st.sensor_angle)
    finally:
        host.close()
        h.stop()


# ------------------------------------------------------------------ sensor boards
def _in_session(path):
    """A host whose session is current (a board sends samples only in a session)."""
    host = fw_host(path)
    assert host.request(m.Ping(0)) == m.Ack(m.Ping.TYPE)
    return host


def _samples(host, cls, seconds):
    """Samples of ``cls`` for ``seconds`` (a board sends samples only in a session)."""
    if host.session is None:
        assert host.request(m.Ping(0)) == m.Ack(m.Ping.TYPE)   # opens it (HELLO) and makes it current
    return [m.decode(f) for f in host.poll(seconds) if f.type == cls.TYPE]


def test_absorber_thermocouples_and_switches(tmp_path):
    from sslfr_drivers.sensors import max6675
    h = _harness('absorber', tmp_path)
    host = _in_session(h.path)
    try:
        h.cmd(f'temps {max6675.encode(31.5, False)} {max6675.encode(148.25, False)}')
        h.cmd('switches 5')
        s = _samples(host, ms.ThermocoupleSample, 2.2)
        assert len(s) >= 3 and all(b.board_ms - a.board_ms == 250 for a, b in zip(s, s[1:]))   # 4 Hz
        last = s[-1]
        assert max6675.decode(last.inlet).temperature == 31.5
        assert max6675.decode(last.outlet).temperature == 148.25
        h.cmd(f'temps {max6675.encode(30, True)} {max6675.encode(150, False)}')  # inlet open
        time.sleep(1.0)
        s = _samples(host, ms.ThermocoupleSample, 0.6)
        assert max6675.decode(s[-1].inlet).fault == max6675.FAULT_OPEN
        sw = [x for x in host.received if x.type == ms.SwitchSample.TYPE]
        assert m.decode(sw[-1]).bits == 5
        host.poll(0.2)
        h.cmd('switches 4 5 4 5 4')                                      # a bouncing contact
        bits = [x.bits for x in _samples(host, ms.SwitchSample, 0.6)]
        assert bits[-1] == 4 and bits.count(5) >= 1, bits                 # raw: the chatter shows
        steady = _samples(host, ms.SwitchSample, 1.0)
        gaps = {b.board_ms - a.board_ms for a, b in zip(steady, steady[1:])}
        assert len(steady) >= 5 and gaps <= {50, 51}, gaps                # 20 Hz when steady
    finally:
        host.close()
        h.stop()


def test_absorber_counts_anemometer_pulses(tmp_path):
    """Issue 35: the cup anemometer's square wave on the pin the host set (D8 here; simavr
    drives the pin the firmware counts on): every falling edge counted; 20 Hz -> 0.765 *
    20 + 0.35 = 15.65 m/s."""
    from sslfr_drivers.sensors import anemometer
    h = _harness('absorber', tmp_path)
    host = _in_session(h.path)
    try:
        assert not _samples(host, ms.PulseSample, 0.6)                  # no input set: no samples
        nack = host.request(ms.SetPulseInput(9))                         # D9: a MAX6675 /CS
        assert nack == m.Nack(ms.SetPulseInput.TYPE, m.ErrorCode.OUT_OF_RANGE)
        assert host.request(ms.SetPulseInput(8)) == m.Ack(ms.SetPulseInput.TYPE)
        h.cmd('pulses 20')
        s = _samples(host, ms.PulseSample, 4.2)
        assert len(s) >= 15 and all(x.pin == 8 for x in s)
        assert all(b.board_ms - a.board_ms == 250 for a, b in zip(s, s[1:]))            # 4 Hz
        rate = (s[-1].count - s[1].count) / ((s[-1].board_ms - s[1].board_ms) / 1000.0)
        assert rate == pytest.approx(20.0, abs=0.3), rate
        counter, stats = anemometer.PulseCounter(), anemometer.WindStats()
        readings = [stats.add(*iv) for x in s[1:] if (iv := counter.add(x.board_ms, x.count))]
        assert readings[-1].speed == pytest.approx(15.65, abs=0.3)
        st = h.status()
        assert abs(st['fw_pulses'] - st['pulses_sent']) <= 1             # every edge counted
        h.cmd('pulses 0')                                                # calm: the count stops
        host.poll(0.6)
        s = _samples(host, ms.PulseSample, 1.2)
        assert len(s) >= 4 and len({x.count for x in s}) == 1
    finally:
        host.close()
        h.stop()


def test_absorber_counts_flow_meter_pulses(tmp_path):
    """Issue 34: the simulated absorber pumping seed 003's 150 L/h through a 450 pulse/L
    meter (sslfr_sim AbsorberSim, flow_lph) drives 18.75 Hz on the pin the host set for
    the flow meter (D8, seed 003's site config), re-commanded at 4 Hz as the firmware
    board's sim does (the wave keeps its phase: a restart per command added an edge
    each, 20 Hz); the firmware counts every edge and the host's flow
    (sslfr_drivers.sensors.thermal) is 150 L/h within 2 %."""
    from sslfr_drivers.sensors import thermal
    from sslfr_sim.sensors import AbsorberSim
    sim = AbsorberSim({'flow_lph': 150.0, 'flow_k_factor': 450.0})
    hz = sim.pulse_frequency()
    assert hz == pytest.approx(18.75)
    h = _harness('absorber', tmp_path)
    host = _in_session(h.path)
    try:
        assert host.request(ms.SetPulseInput(8)) == m.Ack(ms.SetPulseInput.TYPE)
        s = []
        for _ in range(26):
            h.cmd(f'pulses {hz:.4f}')
            s += _samples(host, ms.PulseSample, 0.25)
        assert len(s) >= 22 and all(x.pin == 8 for x in s)
        tracker = thermal.ThermalTracker(450.0, window=5.0)
        out = [tracker.add(x.board_ms, x.count, steady=x.board_ms / 1000.0) for x in s]
        flow, _ = out[-1]
        assert flow.window == pytest.approx(5.0, abs=0.01)
        assert thermal.litres_per_hour(flow.volume_flow) == pytest.approx(150.0, rel=0.02)
        st = h.status()
        assert abs(st['fw_pulses'] - st['pulses_sent']) <= 1             # every edge counted
    finally:
        host.close()
        h.stop()


def test_irradiance_auto_range_covers_0_to_120_klx(tmp_path):
    from sslfr_drivers.sensors import veml7700
    h = _harness('irradiance', tmp_path)
    host = _in_session(h.path)
    try:
        for lux in (2.0, 800.0, 30000.0, 118000.0):
            h.cmd(f'lux {lux}')
            got, prev = None, None
            for _ in range(12):                  # one ladder step per 1 s sample, then stable
                s = _samples(host, ms.AlsSample, 1.05)
                if s:
                    setting = (s[-1].gain_code, s[-1].it_code)
                    if setting == prev:
                        got = veml7700.decode(s[-1].count, *setting)
                        break
                    prev = setting
            assert got is not None and not got.saturated, lux
            assert got.illuminance == pytest.approx(lux, rel=0.01, abs=2 * veml7700.resolution(
                s[-1].gain_code, s[-1].it_code)), lux
        h.cmd('lux 150000')                                # beyond the range: flagged
        time.sleep(1.2)
        s = _samples(host, ms.AlsSample, 1.1)
        assert veml7700.decode(s[-1].count, s[-1].gain_code, s[-1].it_code).saturated
    finally:
        host.close()
        h.stop()


def test_gps_nmea_forwarded_byte_exact(tmp_path):
    from sslfr_sim.world import GpsReceiver
    h = _harness('gps', tmp_path)
    host = _in_session(h.path)
    try:
        rx = GpsReceiver(36.8, -2.4, altitude=10.0, geoid_separation=50.0, noise=2.0, satellites=8,
                         hdop=1.1, ttff=0.0, seed=1)
        sent = b''
        for k in range(3):
            epoch = rx.epoch(1782036000.0 + k)
            sent += epoch
            h.cmd('nmea ' + epoch.hex())
            time.sleep(0.7)                      # ~500 bytes at 9600 bit/s
        chunks = _samples(host, ms.NmeaChunk, 0.5)
        assert b''.join(c.data for c in chunks) == sent
        assert all(len(c.data) <= 64 for c in chunks)
        assert h.status()['frames_out'] >= len(chunks)
    finally:
        host.close()
        h.stop()


def test_uart_bridge_loses_no_byte_when_the_host_stalls(tmp_path):
    """The absorber streams ~24 frames/s; the host does not read for 3 s, then reads
    everything: every frame arrives (no sequence gap)."""
    from sslfr_drivers.link.protocol import SequenceTracker
    h = _harness('absorber', tmp_path)
    host = _in_session(h.path)
    try:
        host.poll(0.3)
        time.sleep(3.0)
        frames = host.poll(0.5)
        t = SequenceTracker()
        for f in frames:
            t.accept(f.seq)
        assert len(frames) > 60 and t.lost == 0 and t.duplicates == 0
        assert h.status()['tx_overflow'] == 0 and h.status()['bytes_dropped'] == 0
    finally:
        host.close()
        h.stop()
