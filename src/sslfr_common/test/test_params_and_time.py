"""sslfr_common.params (the one parameter-table type), its declaration and run-time
guard on a real rclpy node (sslfr_common.node), and the time conversions
(sslfr_common.timeconv)."""
from __future__ import annotations

import math
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_common.params import ParamSpec, ParamTable, writable_directory
from sslfr_common.timeconv import duration, split_seconds, stamp, stamp_from_ns, to_sec


def _table(**kw) -> ParamTable:
    return ParamTable([
        ParamSpec('rate', 1.0, 'Loop rate [Hz]', 'Hz', 0.1, 10.0),
        ParamSpec('speeds', [0.5, 0.5], 'Axis speeds [rad/s]', 'rad/s', 0.0, 1.0, length=2),
        ParamSpec('count', 3, 'Retries [-]', '-', 1, 5),
        ParamSpec('on', True, 'Enabled'),
        ParamSpec('address', '127.0.0.1', 'Where', read_only=True,
                  validator=lambda v: None if v.count('.') == 3 else f'{v!r} is not a dotted address'),
    ], cross_check=lambda v: ['count 5 needs rate < 5 Hz'] if v['count'] == 5 and v['rate'] >= 5 else [],
        **kw)


# ----------------------------------------------------------------- tables (pure)
def test_writable_directory_is_judged_by_a_real_attempt_leaving_nothing(tmp_path):
    assert writable_directory(str(tmp_path)) is None
    assert writable_directory(str(tmp_path / 'new' / 'deeper')) is None      # creatable
    assert writable_directory('') is None and writable_directory('', empty_ok=False)
    assert 'cannot create directories in /proc' in writable_directory('/proc/sslfr_state')
    blocker = tmp_path / 'file'
    blocker.write_text('x')
    assert 'is not a directory' in writable_directory(str(blocker / 'sub'))
    assert 'is not a directory' in writable_directory(str(blocker))
    assert sorted(p.name for p in tmp_path.iterdir()) == ['file']             # nothing left behind


def test_checks_types_ranges_validators_and_cross_rules():
    t = _table()
    assert t.validate(t.defaults()) == []
    by = t.by_name
    assert 'expected a bool' in by['on'].check(1)
    assert by['rate'].check(math.nan) and by['rate'].check(11.0).startswith('rate: 11.0 Hz')
    assert by['address'].check('localhost') == "address: 'localhost' is not a dotted address"
    assert by['address'].check(5).startswith('address: expected a string')     # type first
    assert t.validate({**t.defaults(), 'count': 5, 'rate': 6.0}) == ['count 5 needs rate < 5 Hz']
    # the cross check runs only on individually valid values
    assert t.validate({**t.defaults(), 'count': 5, 'rate': 60.0}) == ['rate: 60.0 Hz is outside [0.1, 10.0]']


def test_integers_for_floats():
    strict, lenient = _table(), _table(integers_for_floats=True)
    assert lenient.coerce({'rate': 2, 'speeds': [1, 0.5], 'count': 2, 'on': True, 'x': 1}) == \
        {'rate': 2.0, 'speeds': [1.0, 0.5], 'count': 2, 'on': True, 'x': 1}
    assert isinstance(lenient.coerce({'rate': 2})['rate'], float)
    # a site config's section: rclpy refuses 2 for a double unless the node takes it
    assert 'is an integer' in strict.check_overrides({'rate': 2})[0]
    assert lenient.check_overrides({'rate': 2}) == []
    assert 'did you mean rate' in lenient.check_overrides({'rtae': 2.0})[0]
    assert lenient.with_defaults(rate=2.0).integers_for_floats


# ----------------------------------------------------------------- on a node
def test_declare_parameters_and_guard_on_a_node(ros_domain):
    import rclpy
    from rclpy.parameter import Parameter
    from sslfr_common.node import ParameterGuard, declare_parameters

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    try:
        table = _table(integers_for_floats=True)
        node = rclpy.create_node('params_demo', context=ctx,
                                 parameter_overrides=[Parameter('rate', value=2)])
        values = declare_parameters(node, table)
        assert values == {'rate': 2.0, 'speeds': [0.5, 0.5], 'count': 3, 'on': True, 'address': '127.0.0.1'}
        assert isinstance(values['rate'], float)
        d = node.describe_parameter('rate')
        assert d.floating_point_range[0].to_value == 10.0 and 'unit: Hz' in d.additional_constraints
        assert node.describe_parameter('count').integer_range[0].from_value == 1
        assert node.describe_parameter('address').read_only

        applied = []

        def apply(v):
            if v['count'] == 4:
                raise ValueError('count: 4 is not allowed by the core')
            applied.append(v)
        guard = ParameterGuard(node, table, values, apply)
        r = node.set_parameters([Parameter('rate', value=6)])[0]          # an integer for a double
        assert r.successful, r.reason
        assert guard.values['rate'] == 6.0 and isinstance(applied[-1]['rate'], float)
        r = node.set_parameters([Parameter('count', value=5)])[0]         # cross rule
        assert not r.successful and r.reason == 'count 5 needs rate < 5 Hz'
        r = node.set_parameters([Parameter('count', value=4)])[0]         # apply() refuses
        assert not r.successful and 'not allowed by the core' in r.reason
        r = node.set_parameters([Parameter('rate', value='fast')])[0]     # dynamic typing: we judge
        assert not r.successful and r.reason.startswith('rate: expected a number')
        r = node.set_parameters([Parameter('rate', Parameter.Type.NOT_SET)])[0]
        assert not r.successful and r.reason == 'rate: cannot be unset'
        assert guard.refused == 4 and guard.last_refusal == 'rate: cannot be unset'
        assert node.get_parameter('count').value == 3 and node.get_parameter('rate').value == 6
        assert guard.values == {**values, 'rate': 6.0} and len(applied) == 1
        node.destroy_node()

        # start-up: every bad value in one line (rclpy's refusals and the table's)
        bad = rclpy.create_node('params_bad', context=ctx, parameter_overrides=[
            Parameter('rate', value=50.0), Parameter('address', value='localhost')])
        with pytest.raises(ValueError) as exc:
            declare_parameters(bad, table)
        assert 'rate:' in str(exc.value)
        bad.destroy_node()
        bad = rclpy.create_node('params_bad2', context=ctx, parameter_overrides=[
            Parameter('address', value='localhost'), Parameter('speeds', value=[0.5, 3.0])])
        with pytest.raises(ValueError) as exc:
            declare_parameters(bad, table)
        assert str(exc.value) == ('speeds: 3.0 rad/s is outside [0.0, 1.0]; '
                                  "address: 'localhost' is not a dotted address")
        bad.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


# ----------------------------------------------------------------- time
def test_time_conversions():
    assert split_seconds(1782036000.25) == (1782036000, 250_000_000)
    assert split_seconds(-0.25) == (-1, 750_000_000)
    assert split_seconds(2.9999999999) == (3, 0)
    t = stamp(1782036000.25)
    assert (t.sec, t.nanosec) == (1782036000, 250_000_000) and to_sec(t) == 1782036000.25
    d = duration(-1.5)
    assert (d.sec, d.nanosec) == (-2, 500_000_000) and to_sec(d) == -1.5
    ns = 1_782_036_000_123_456_789
    t = stamp_from_ns(ns)
    assert (t.sec, t.nanosec) == (1_782_036_000, 123_456_789)
    assert to_sec(ns) == pytest.approx(1782036000.123456789, abs=1e-6)
    from rclpy.duration import Duration
    assert to_sec(Duration(seconds=2, nanoseconds=5)) == pytest.approx(2.000000005, abs=1e-15)
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError):
            stamp(bad)


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=-2e9, max_value=4e9, allow_nan=False))
def test_split_seconds_is_the_nearest_nanosecond(x):
    sec, nanosec = split_seconds(x)
    assert 0 <= nanosec < 1_000_000_000
    assert abs(Fraction(x) - (sec + Fraction(nanosec, 1_000_000_000))) <= Fraction(1, 2_000_000_000)
