"""Check a simulated day against the ephemeris: the numbers the system scenario tests
assert on. Pure Python + numpy (no rclpy). The day itself is read with
:func:`sslfr_recording.day.read_day` and its ideal built with
:func:`sslfr_recording.day.reference` (the run's collector at the planner's site).

- :func:`tracking_error` compares each axis' measured angle with the ideal command
  (seed 000 eqs. 9-13 and the collector's longitudinal law) for the same site and
  collector;
- :func:`run_sim` runs ``sslfr sim`` as a process and finds its bag.

Time quantisation in simulation. At ``--speed X`` the drivers poll their board on a
steady (wall) clock and ``/clock`` advances in steps, so a measured angle stamped
``t`` belongs to a setpoint between ``t - lag`` and ``t`` with
``lag = X * (wall latency)``. :func:`tracking_error` therefore reports the distance
from the measured angle to the ideal angles over ``[t - lag, t]`` (zero lag: the
plain difference), and the tests bound it by one motor step plus the position
sensor noise.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np



def interval_distance(value: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from ``value`` to the closed interval between ``a`` and ``b`` (any order)."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.maximum(0.0, np.maximum(lo - value, value - hi))


def tracking_error(t: np.ndarray, measured: np.ndarray, ideal_fn, lag: float = 0.0,
                   samples: int = 8) -> np.ndarray:
    """|measured - ideal| [rad] allowing the measurement to lag by up to ``lag`` [s].

    Parameters
    ----------
    t : numpy.ndarray
        Stamps of the measurements [s since the Unix epoch].
    measured : numpy.ndarray
        Measured joint angles [rad].
    ideal_fn : callable
        ``ideal_fn(t_array) -> angles [rad]``, e.g. a column of
        ``sslfr_planner.tracking_table.evaluate``.
    lag : float
        Allowed lag [s] (>= 0); the ideal path over ``[t - lag, t]`` is sampled at
        ``samples`` points and the distance to the nearest is returned.
    """
    t = np.asarray(t, dtype=float)
    measured = np.asarray(measured, dtype=float)
    if lag <= 0:
        return np.abs(measured - ideal_fn(t))
    best = np.full(t.shape, np.inf)
    prev = ideal_fn(t - lag)
    for k in range(1, samples + 1):
        cur = ideal_fn(t - lag + lag * k / samples)
        best = np.minimum(best, interval_distance(measured, prev, cur))
        prev = cur
    return best


# ------------------------------------------------------------------------------ running
def run_sim(args: list[str], env: dict, out: str | Path, timeout: float = 300.0):
    """Run ``sslfr sim ARGS --out OUT`` as a process; return
    ``(completed_process, summary dict from OUT/sim.json, newest bag dir or None)``."""
    import json
    import os
    import subprocess

    root = Path(os.environ.get('SSLFR_ROOT') or Path(__file__).resolve().parents[3])
    out = Path(out)
    proc = subprocess.run([str(root / 'sslfr'), 'sim', *args, '--out', str(out)], env=env,
                          capture_output=True, text=True, timeout=timeout)
    summary = json.loads((out / 'sim.json').read_text()) if (out / 'sim.json').exists() else {}
    bags = sorted((p for p in (Path(summary['bags']).iterdir() if summary.get('bags') else [])
                   if (p / 'metadata.yaml').exists()), key=lambda p: p.stat().st_mtime)
    return proc, summary, (bags[-1] if bags else None)
