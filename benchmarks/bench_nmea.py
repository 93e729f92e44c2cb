"""Throughput of the NMEA stream decoder (sslfr_drivers.sensors.nmea.NmeaStream).

Prints sentences per second for the full stream path (byte reassembly, checksum,
pynmeagps parse, fix/time records) fed in 64-byte chunks, and the ratio to bare
``pynmeagps.NMEAReader.parse`` on the same pre-split sentences (the peer). A GPS
produces ~4-8 sentences per second, so anything above 1e3 /s is ample for a Pi.

Usage: python benchmarks/bench_nmea.py [epochs]
"""
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'sslfr_drivers'))

from pynmeagps import NMEAReader  # noqa: E402

from sslfr_drivers.sensors import nmea  # noqa: E402
from sslfr_sim.world import GpsReceiver  # noqa: E402


def main(epochs: int = 2000) -> None:
    g = GpsReceiver(36.8352778, -2.4022222, ttff=0.0)
    data = b''.join(g.epoch(1774094400.0 + k) for k in range(epochs))
    lines = [ln + b'\r\n' for ln in data.split(b'\r\n') if ln]
    t0 = time.perf_counter()
    s = nmea.NmeaStream()
    n_rec = 0
    for i in range(0, len(data), 64):
        n_rec += len(s.feed(data[i:i + 64], 0.0))
    t_stream = time.perf_counter() - t0
    t0 = time.perf_counter()
    for ln in lines:
        NMEAReader.parse(ln)
    t_peer = time.perf_counter() - t0
    n = len(lines)
    print(f'sentences              {n}')
    print(f'NmeaStream             {n / t_stream:10.0f} sentences/s ({t_stream / n * 1e6:.1f} us each), '
          f'{n_rec} records')
    print(f'pynmeagps parse only   {n / t_peer:10.0f} sentences/s ({t_peer / n * 1e6:.1f} us each)')
    print(f'ratio stream / peer    {t_stream / t_peer:10.2f} x the time')


if __name__ == '__main__':
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2000)
