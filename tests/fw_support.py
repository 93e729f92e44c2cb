"""Shared helpers of the firmware tests (tests/test_fw_*.py).

:func:`require` builds the firmware parts a test needs (``make -C firmware``) and skips
the test with the reason (printed in pytest's summary, ``-ra``) when the toolchain is
missing; with ``CI=true`` a missing toolchain FAILS instead (CI must run them).
"""
from __future__ import annotations

import os

import pytest

from drivers_testutil import RawHost, wait_for  # noqa: F401 - one polling helper for every test package


#: the installation key of the firmware tests (fresh for every run: nothing depends on a
#: key file in $HOME); the harnesses start with it in EEPROM (a provisioned board)
KEY = os.urandom(16)


def provisioned(record, key: bytes | None = KEY, boot_count: int | None = None) -> bytes:
    """The EEPROM image of a board configured with ``record`` and provisioned with ``key``."""
    from sslfr_drivers.firmware import eeprom_image
    return eeprom_image(record, key, boot_count)


def fw_host(path: str, key: bytes | None = KEY) -> RawHost:
    """A byte-level host with the tests' key that opens a session before its first request
    (what the board sent before, its BOOT, stays readable)."""
    return RawHost(path, key=key, auto_session=True, flush=False)


def require(*parts: str) -> None:
    """Build ``parts`` ('firmware', 'sim', 'host'); skip / fail (CI) when impossible."""
    from sslfr_drivers import firmware as fw
    targets = {'firmware': 'all', 'sim': 'sim', 'host': 'host'}
    problem = fw.toolchain_problem(*parts)
    if problem:
        if os.environ.get('CI', '').lower() in ('1', 'true', 'yes'):
            pytest.fail(f'CI=true and {problem}')
        pytest.skip(problem)
    try:
        fw.build(*(targets[p] for p in parts))
    except fw.FirmwareError as exc:
        pytest.fail(str(exc))
