"""The loss table (sslfr_common.tracking_loss) is the ray trace's seed 000 section 5.2
study, recomputed here so the numbers cannot drift from the analysis."""
from __future__ import annotations

import math
from datetime import date

import numpy as np
import pytest

from sslfr_planner.analysis import performance
from sslfr_planner.analysis.optics import OpticalParameters
from sslfr_planner.analysis.performance import AnalysisSite
from sslfr_common.tracking_loss import LOSS_TABLE, estimated_loss, loss_text

ALMERIA = AnalysisSite(36 + 50 / 60 + 7 / 3600, -(2 + 24 / 60 + 8 / 3600), 22.0)
DAYS = [date(2024, 3, 21), date(2024, 6, 21), date(2024, 9, 21), date(2024, 12, 21)]


def test_table_equals_the_ray_trace():
    errors = [e for e, _, _ in LOSS_TABLE]
    rows = performance.error_table(ALMERIA, OpticalParameters(), np.radians(errors), DAYS, [9.0, 12.0, 15.0])
    for e, low, high in LOSS_TABLE:
        losses = [r.loss_total for r in rows if abs(np.degrees(r.error) - e) < 1e-9]
        assert len(losses) == 12
        assert min(losses) == pytest.approx(low, abs=0.006), e
        assert max(losses) == pytest.approx(high, abs=0.006), e


def test_interpolation_and_the_seed_figures():
    assert estimated_loss(math.radians(0.06))[:2] == (0.0, 0.2)
    low, high, beyond = estimated_loss(-math.radians(0.36))        # either sign
    assert (low, high, beyond) == (2.47, 3.38, False)
    low, high, _ = estimated_loss(math.radians(0.33))
    assert low == pytest.approx((1.75 + 2.47) / 2) and high == pytest.approx((2.56 + 3.38) / 2)
    assert estimated_loss(math.radians(2.0)) == (41.41, 55.32, True)
    assert math.isnan(estimated_loss(math.nan)[0])
    assert loss_text(math.radians(0.36)) == 'estimated optical loss 2.5-3.4 %'
    assert loss_text(math.radians(3.0)).startswith('estimated optical loss >= 41.4')
    assert 'not estimated' in loss_text(0.01, 'secondary_reflector')
