"""Fixtures shared by the gateway's tests (imported by name: a second conftest.py would
shadow the root one's `from conftest import ...` under pytest-xdist)."""
from __future__ import annotations

import socket

import pytest


@pytest.fixture
def extra_loopbacks() -> list[str]:
    """The loopback addresses besides 127.0.0.1 this machine can bind (127.0.0.2/3 on a
    127.0.0.0/8 loopback): other client addresses for flood and allow-list tests."""
    def bindable(addr: str) -> bool:
        try:
            with socket.socket() as s:
                s.bind((addr, 0))
            return True
        except OSError:
            return False
    return [a for a in ('127.0.0.2', '127.0.0.3') if bindable(a)]
