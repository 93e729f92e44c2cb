"""Authenticated board links seen from the axis driver node (issue 19): the node reads
its key from the ``key_file`` parameter; a board provisioned with another key, or a key
file other users may read, is a LINK_FAULT with the reason in ``axes/<axis>/status``
(board_info) and in diagnostics, never silence; the matching key drives the axis."""
from __future__ import annotations

import os

from test_axis_driver import rig  # noqa: F401 - the fixture

from sslfr_drivers.link.keys import generate, write_key_file


def _refused(r, ros, text: str) -> bool:
    return ros.spin_until(lambda: bool(r.status) and r.status[-1].link_state == 3
                          and text in r.status[-1].board_info and text in r.diag().get('last_error', ''), 20)


def test_key_file_parameter_wrong_key_and_exposed_key(rig, ros, tmp_path):  # noqa: F811
    site = write_key_file(tmp_path / 'site.key', generate())
    other = write_key_file(tmp_path / 'other.key', generate())
    good = rig(sim_args=['--key-file', str(site), '--opt', 'initial_angle_deg=0'],
               params={'key_file': str(site)})
    wrong = rig(axis='mobile_structure', sim_args=['--key-file', str(site)], params={'key_file': str(other)})
    exposed = write_key_file(tmp_path / 'exposed.key', generate())
    os.chmod(exposed, 0o644)
    open_file = rig(axis='secondary_reflector', sim_args=['--key-file', str(site)],
                    params={'key_file': str(exposed)})
    assert ros.spin_until(lambda: bool(good.status) and good.status[-1].link_state == 2, 20), good.driver.output()
    assert 'sslfr-axis' in good.status[-1].board_info or 'sim' in good.status[-1].board_info
    assert _refused(wrong, ros, "does not accept this host's key"), (wrong.status[-1:], wrong.driver.output())
    assert wrong.board()['homed'] is False and wrong.board()['counter'] == 0        # never driven
    assert _refused(open_file, ros, 'readable by every user'), open_file.driver.output()
    assert 'chmod 600' in open_file.diag()['last_error']
