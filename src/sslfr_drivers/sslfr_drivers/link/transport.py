"""Byte transports under the reconnecting reader (:mod:`sslfr_drivers.link.reader`) of a
:class:`~sslfr_drivers.link.board_link.BoardLink` or a raw NMEA source (no rclpy).

* :class:`SerialTransport` - any pyserial URL or device: ``/dev/ttyUSB0``,
  ``/dev/serial0``, a pty slave such as ``/dev/pts/7`` (what the simulated boards
  expose), ``loop://`` (loop-back, for tests), ``socket://host:port``.
* :class:`XBeeCoordinator` + :class:`XBeeBoardTransport` - XBee 802.15.4 in API
  mode with escaping (AP=2) through digi-xbee. ONE coordinator object owns the
  local XBee's UART; every remote board is a logical transport addressed by its
  64-bit address. Each write is one TX64 request whose transmit status is checked:
  a failed status raises :class:`TransmitError` and is counted per board
  (``tx_failures``) and per coordinator.

:func:`make_transport` turns a ``port`` string into a transport:
``xbee:<serial port>?addr=<16 hex digits>[&baud=<bps>]`` selects the XBee path
(coordinators are shared per serial port inside a process); anything else is a
pyserial URL or device path.

Every transport has ``open()``, ``close()``, ``is_open``, ``write(data)``,
``read(timeout) -> bytes`` (returns ``b''`` on timeout) and ``interrupt()`` (ends a
read under way early, from another thread, where ``interruptible``). Port loss raises
:class:`TransportError` from ``read``/``write``; the reader that owns the transport
then closes it and reopens it with back-off.
"""
from __future__ import annotations

import logging
import os
import queue
import select
import threading
import urllib.parse

import serial

_log = logging.getLogger(__name__)

#: [bytes] most taken by one read of a POSIX port: a burst of frames at 115200 bit/s
#: between two reads of a loaded reader
READ_CHUNK = 4096


class TransportError(OSError):
    """The port is gone or unusable (unplugged, pty closed, coordinator down)."""


class TransmitError(TransportError):
    """One frame could not be delivered (XBee transmit status not OK). The port is
    still usable; the link counts it and retries by its own timeouts."""


class Transport:
    """Interface of a byte transport (see module docstring)."""

    name = 'transport'

    def open(self) -> None:
        """Open the port; TransportError when it cannot be opened."""
        raise NotImplementedError

    def close(self) -> None:
        """Close the port (idempotent)."""
        raise NotImplementedError

    @property
    def is_open(self) -> bool:
        """True while the port is open."""
        raise NotImplementedError

    def write(self, data: bytes) -> None:
        """Write all of ``data``; TransportError when the port is gone."""
        raise NotImplementedError

    def read(self, timeout: float) -> bytes:
        """Bytes available within ``timeout`` [s] (b'' when none);
        TransportError when the port is gone."""
        raise NotImplementedError

    @property
    def tx_failures(self) -> int:
        """Frames the transport could not deliver (XBee transmit status)."""
        return 0

    @property
    def interruptible(self) -> bool:
        """True when :meth:`interrupt` can end a read under way."""
        return False

    def interrupt(self) -> None:
        """End the read under way (or the next one) early with ``b''``; a no-op where
        not :attr:`interruptible`. Safe from any thread."""


class SerialTransport(Transport):
    """pyserial port (URL or device path).

    Parameters
    ----------
    url : str
        ``serial.serial_for_url`` URL or device path.
    baudrate : int
        Line speed [bit/s] (ignored by ptys and ``loop://``).
    """

    def __init__(self, url: str, baudrate: int = 115200):
        self.url = url
        self.name = url
        self.baudrate = baudrate
        self._ser: serial.SerialBase | None = None
        self._wlock = threading.Lock()

    def open(self) -> None:
        if self._ser is not None:
            return
        try:
            ser = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0.02,
                                        write_timeout=1.0, do_not_open=True)
            if hasattr(ser, 'exclusive') and not self.url.startswith(('loop://', 'socket://')):
                try:
                    ser.exclusive = True
                except (ValueError, serial.SerialException):
                    pass
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise TransportError(f'cannot open {self.url}: {exc}') from None
        self._ser = ser

    def close(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass

    @property
    def is_open(self) -> bool:
        return self._ser is not None

    @property
    def interruptible(self) -> bool:
        # pyserial's POSIX ports (devices, ptys) wait in select() on an abort pipe too
        return hasattr(self._ser, 'pipe_abort_read_w')

    def interrupt(self) -> None:
        ser = self._ser
        if ser is not None and hasattr(ser, 'pipe_abort_read_w'):
            try:
                ser.cancel_read()
            except (OSError, TypeError):
                pass

    def write(self, data: bytes) -> None:
        ser = self._ser
        if ser is None:
            raise TransportError(f'{self.url} is not open')
        try:
            with self._wlock:
                ser.write(data)
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise TransportError(f'write to {self.url} failed: {exc}') from None

    def read(self, timeout: float) -> bytes:
        """Return what is available (at least 1 byte) or ``b''`` after ``timeout`` [s].

        A POSIX port (a device, a pty) is read with one ``select`` on its descriptor
        and pyserial's abort pipe (:meth:`interrupt`) and one ``os.read`` of what is
        there: pyserial's own path changes the port's timeout (``flock``,
        ``tcgetattr``, ``tcsetattr``) whenever the wait changes, which here is at
        every read, then reads a byte, asks how many wait and reads them (seven
        system calls instead of two, at every frame of every board). Other URLs
        (``loop://``, ``socket://``) take pyserial's path."""
        ser = self._ser
        if ser is None:
            raise TransportError(f'{self.url} is not open')
        fd, abort = getattr(ser, 'fd', None), getattr(ser, 'pipe_abort_read_r', None)
        if isinstance(fd, int) and isinstance(abort, int):
            return self._read_fd(fd, abort, timeout)
        try:
            if ser.timeout != timeout:
                ser.timeout = timeout
            data = ser.read(1)
            if data:
                n = ser.in_waiting
                if n:
                    data += ser.read(n)
            return data
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise TransportError(f'read from {self.url} failed: {exc}') from None

    def _read_fd(self, fd: int, abort: int, timeout: float) -> bytes:
        try:
            ready, _, _ = select.select([fd, abort], [], [], max(0.0, timeout))
            if abort in ready:
                os.read(abort, 1000)         # interrupted: the poke's byte(s) consumed
                if fd not in ready:
                    return b''
            if not ready:
                return b''
            data = os.read(fd, READ_CHUNK)
        except BlockingIOError:
            return b''                       # ready, then taken by nobody else: nothing after all
        except (OSError, ValueError) as exc:  # ValueError: the descriptor was closed meanwhile
            raise TransportError(f'read from {self.url} failed: {exc}') from None
        if not data:                         # readable but empty: the device is gone (as pyserial)
            raise TransportError(f'read from {self.url} failed: the device reports readiness but '
                                 'returned no data (unplugged, or another process on the port?)')
        return data


# --------------------------------------------------------------------------- XBee
class _DigiLogForward(logging.Handler):
    """digi-xbee's own log records, as one line each (no traceback) on this module's
    logger (which the nodes forward to theirs): without a handler of its own,
    Python's last-resort handler would print them, tracebacks included, on stderr."""

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= logging.WARNING:
            _log.log(record.levelno, 'XBee library: %s', record.getMessage())


_digi_log = logging.getLogger('digi')
if not any(isinstance(h, _DigiLogForward) for h in _digi_log.handlers):
    _digi_log.addHandler(_DigiLogForward())
    _digi_log.propagate = False       # only the one-line forward, whatever the root logger does


def _port_loss_aware_serial(port: str, baudrate: int, timeout: float):
    """digi-xbee's serial interface, except that a port which reports data but returns
    none (a USB coordinator unplugged, the far end of a pty closed) ends the library's
    reader thread instead of making it retry forever (a busy loop and a warning per
    retry): the reader then closes the port, :attr:`XBeeCoordinator.is_open` turns
    False, and the owner reopens it with back-off."""
    from digi.xbee.serial import XBeeSerialPort

    class PortLossAwareSerialPort(XBeeSerialPort):
        def wait_for_frame(self, operating_mode):
            try:
                return super().wait_for_frame(operating_mode)
            except serial.SerialException as exc:
                if 'returned no data' in str(exc):
                    raise serial.SerialException(f'XBee coordinator port {port} lost') from None
                raise

    return PortLossAwareSerialPort(baudrate, port, timeout=timeout)


class XBeeCoordinator:
    """The one owner of a local XBee (802.15.4, API mode AP=2) on a serial port.

    Parameters
    ----------
    port : str
        Serial device of the local (coordinator) XBee.
    baudrate : int
        UART speed [bit/s] (XBee default 9600).
    sync_timeout : float
        How long a transmission waits for its TX status [s].

    Notes
    -----
    ``open()`` uses digi-xbee's ``Raw802Device.open()``, which reads the local
    module's parameters (AP, HV, VR, SH, SL, NI, MY, CE) with AT commands; the
    simulated coordinator (``sslfr_sim.xbee``) answers them. Transmission
    uses digi-xbee's packet classes (see :meth:`send`). Counters:
    ``tx_ok``, ``tx_failures``, ``rx_frames``, ``rx_unknown`` (data from an address no
    board transport is registered for).
    """

    def __init__(self, port: str, baudrate: int = 9600, sync_timeout: float = 1.0):
        self.port = port
        self.baudrate = baudrate
        self.sync_timeout = sync_timeout
        self._dev = None
        self._lock = threading.RLock()
        self._boards: dict[bytes, XBeeBoardTransport] = {}
        self.tx_ok = 0
        self.tx_failures = 0
        self.rx_frames = 0
        self.rx_unknown = 0
        self.local_address: str | None = None
        self._frame_id = 0
        self._tx_waits: dict[int, tuple[threading.Event, list]] = {}

    @property
    def is_open(self) -> bool:
        dev = self._dev
        return dev is not None and dev.is_open() and dev.comm_iface.is_interface_open

    def open(self) -> None:
        """Open the UART and read the local XBee's identity (idempotent)."""
        from digi.xbee.devices import Raw802Device
        from digi.xbee.exception import XBeeException
        from digi.xbee.models.mode import OperatingMode
        with self._lock:
            if self.is_open:
                return
            self.close()
            dev = Raw802Device(comm_iface=_port_loss_aware_serial(self.port, self.baudrate, self.sync_timeout))
            dev.set_sync_ops_timeout(self.sync_timeout)
            try:
                dev.open()
            except (XBeeException, serial.SerialException, OSError) as exc:
                try:
                    dev.close()
                except Exception:  # noqa: BLE001 - best effort cleanup of a failed open
                    pass
                raise TransportError(f'cannot open XBee coordinator on {self.port}: {exc}') from None
            if dev.operating_mode != OperatingMode.ESCAPED_API_MODE:
                _log.warning('XBee on %s is in %s, expected escaped API mode (AP=2)',
                             self.port, dev.operating_mode)
            dev.add_data_received_callback(self._on_data)
            dev.add_packet_received_callback(self._on_packet)
            self.local_address = str(dev.get_64bit_addr())
            self._dev = dev

    def close(self) -> None:
        with self._lock:
            dev, self._dev = self._dev, None
            if dev is not None:
                try:
                    dev.close()
                except Exception:  # noqa: BLE001 - closing a dead port may raise anything
                    pass

    def attach(self, board: 'XBeeBoardTransport') -> None:
        self._boards[board.address] = board

    def detach(self, board: 'XBeeBoardTransport') -> None:
        """Forget ``board``; the UART is closed when the last board detaches."""
        with self._lock:
            self._boards.pop(board.address, None)
            if not self._boards:
                self.close()

    def _on_data(self, message) -> None:
        self.rx_frames += 1
        addr = bytes(message.remote_device.get_64bit_addr().address)
        board = self._boards.get(addr)
        if board is None:
            self.rx_unknown += 1
            return
        board._deliver(bytes(message.data))

    def _on_packet(self, packet) -> None:
        """digi-xbee packet callback: complete the wait of a TX status' frame id."""
        from digi.xbee.packets.raw import TXStatusPacket
        if isinstance(packet, TXStatusPacket):
            wait = self._tx_waits.get(packet.frame_id)
            if wait is not None:
                wait[1].append(packet.transmit_status)
                wait[0].set()

    def _next_frame_id(self) -> int:
        with self._lock:
            self._frame_id = self._frame_id % 255 + 1      # 1..255 (0 = no status)
            return self._frame_id

    def send(self, address: bytes, data: bytes) -> None:
        """Transmit ``data`` (<= 100 bytes) to ``address`` (8 bytes) as one TX64 API
        frame and wait for its TX status (``sync_timeout``).

        Raises :class:`TransmitError` on a status other than SUCCESS or no status,
        :class:`TransportError` if the port is gone.

        Notes
        -----
        The frame is built with digi-xbee's ``TX64Packet`` and sent with
        ``send_packet(sync=False)``; the status (``TXStatusPacket``) is matched by
        frame id in a packet callback registered once, and awaited on an Event
        created *before* sending. digi-xbee's own synchronous ``send_data_64`` was
        not used: its ``SyncRequestSender`` can miss a status that arrives before it
        starts waiting and then blocks for the whole timeout (seen in
        benchmarks/bench_link_latency.py: ~3 % of sends took 1 s).
        """
        from digi.xbee.exception import XBeeException
        from digi.xbee.models.address import XBee64BitAddress
        from digi.xbee.models.status import TransmitStatus
        from digi.xbee.packets.raw import TX64Packet
        dev = self._dev
        if dev is None or not self.is_open:
            raise TransportError(f'XBee coordinator on {self.port} is not open')
        fid = self._next_frame_id()
        wait: tuple[threading.Event, list] = (threading.Event(), [])
        self._tx_waits[fid] = wait
        try:
            packet = TX64Packet(fid, XBee64BitAddress(address), 0, bytes(data),
                                op_mode=dev.operating_mode)
            dev.send_packet(packet, sync=False)
            got = wait[0].wait(self.sync_timeout)
        except (XBeeException, serial.SerialException, OSError) as exc:
            self.close()
            raise TransportError(f'XBee coordinator on {self.port} failed: {exc}') from None
        finally:
            self._tx_waits.pop(fid, None)
        if not got:
            self.tx_failures += 1
            raise TransmitError(f'XBee transmit to {address.hex()}: no TX status in '
                                f'{self.sync_timeout} s')
        status = wait[1][0]
        if status != TransmitStatus.SUCCESS:
            self.tx_failures += 1
            raise TransmitError(f'XBee transmit to {address.hex()} failed: '
                                f'{getattr(status, "description", status)}')
        self.tx_ok += 1


class XBeeBoardTransport(Transport):
    """One remote board behind an :class:`XBeeCoordinator`, by 64-bit address."""

    def __init__(self, coordinator: XBeeCoordinator, address: str | bytes):
        if isinstance(address, str):
            address = bytes.fromhex(address.replace(':', '').replace(' ', ''))
        if len(address) != 8:
            raise ValueError(f'XBee 64-bit address must be 8 bytes, got {address!r}')
        self.coordinator = coordinator
        self.address = bytes(address)
        self.name = f'xbee:{coordinator.port}?addr={self.address.hex().upper()}'
        self._rx: queue.Queue[bytes] = queue.Queue()
        self._open = False
        self._tx_failures = 0

    def open(self) -> None:
        self.coordinator.open()
        self.coordinator.attach(self)
        self._open = True

    def close(self) -> None:
        self._open = False
        self.coordinator.detach(self)

    @property
    def is_open(self) -> bool:
        return self._open

    @property
    def tx_failures(self) -> int:
        return self._tx_failures

    def _deliver(self, data: bytes) -> None:
        self._rx.put(data)

    @property
    def interruptible(self) -> bool:
        return True

    def interrupt(self) -> None:
        self._rx.put(b'')           # read() returns what it has, possibly nothing

    def write(self, data: bytes) -> None:
        if not self._open:
            raise TransportError(f'{self.name} is not open')
        try:
            self.coordinator.send(self.address, data)
        except TransmitError:
            self._tx_failures += 1
            raise

    def read(self, timeout: float) -> bytes:
        if not self._open:
            raise TransportError(f'{self.name} is not open')
        if not self.coordinator.is_open:
            raise TransportError(f'XBee coordinator on {self.coordinator.port} is down')
        try:
            data = self._rx.get(timeout=timeout)
        except queue.Empty:
            return b''
        while True:
            try:
                data += self._rx.get_nowait()
            except queue.Empty:
                return data


_coordinators: dict[str, XBeeCoordinator] = {}
_coord_lock = threading.Lock()


def shared_coordinator(port: str, baudrate: int = 9600) -> XBeeCoordinator:
    """The process-wide coordinator for ``port`` (created on first use): several
    board transports in one process share one UART owner."""
    with _coord_lock:
        coord = _coordinators.get(port)
        if coord is None:
            coord = _coordinators[port] = XBeeCoordinator(port, baudrate)
        return coord


def make_transport(port: str, baudrate: int = 115200) -> Transport:
    """Transport for a ``port`` string (see module docstring for the forms)."""
    if port.startswith('xbee:'):
        parsed = urllib.parse.urlsplit(port)
        query = urllib.parse.parse_qs(parsed.query)
        if 'addr' not in query:
            raise ValueError(f'{port!r}: an xbee: port needs ?addr=<64-bit hex address>')
        serial_port = port[len('xbee:'):].split('?', 1)[0]
        baud = int(query.get('baud', ['9600'])[0])
        return XBeeBoardTransport(shared_coordinator(serial_port, baud), query['addr'][0])
    return SerialTransport(port, baudrate)

