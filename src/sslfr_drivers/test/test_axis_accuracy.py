"""The axis driver's accuracy parameters (sslfr_common.accuracy.PARAM_SPECS in the
driver's table): units, ranges, the cross-check."""
from __future__ import annotations

import math

import pytest

from sslfr_common.accuracy import PARAM_SPECS, cross_check
from sslfr_drivers.axis.params import PARAMS, params_for

D = math.radians


def test_parameters_declared_with_units_ranges_and_refused_when_invalid():
    names = {s.name for s in PARAM_SPECS}
    table = params_for('mirrors')
    assert names <= set(table.by_name)
    for s in PARAM_SPECS:
        assert s.unit and s.description
    p = table.defaults()
    assert table.validate(p) == []
    assert p['accuracy.warn_threshold'] == pytest.approx(D(0.06))
    assert p['accuracy.error_threshold'] == pytest.approx(D(0.36))
    bad = dict(p, **{'accuracy.warn_threshold': D(0.4)})
    assert any('must be below' in e for e in table.validate(bad))
    assert cross_check(bad)
    assert table.validate(dict(p, **{'accuracy.window': -1.0}))
    assert table.validate(dict(p, **{'accuracy.error_threshold': 0.0}))
    assert PARAMS.by_name['accuracy.window'].unit == 's'
