"""
The drive's ROS-free closed loop (``evaluation/drive_core.py``) on the floor's short route.

The head, the map-free driver centring the locator's target, the locator
with odometry and the map-guided gaze, frames rendered with motion blur:
what ``make demo`` runs over DDS, without the processes, so that what the
design gives (the card layout, the gaze, the covariance) is checked apart
from the machine's load. No timing is asserted.
"""

from pattern_locator.evaluation.drive_core import DriveCoreConfig, run, summarise
import pytest


@pytest.fixture(scope='module')
def short_route():
    records = run(DriveCoreConfig(route='short', driver='target', seed=1))
    return records, summarise(records)


def test_the_short_route_has_a_fix_nearly_all_the_time(short_route):
    records, s = short_route
    assert s['images'] >= 150 and s['located'] >= 0.8 * s['images'], s
    # The floor's layout leaves no stretch without a card the head can aim at
    # (docs/deploying.md): 96 % of the driving time has a fix younger than 0.5 s.
    assert s['fix_coverage'] >= 0.9, s['fix_coverage']
    assert s['wrong_ids'] == 0 and s['wrong_rooms'] == 0


def test_the_short_route_errors_and_ellipses(short_route):
    _, s = short_route
    error = s['error_m']
    assert error['median'] <= 0.01 and error['p95'] <= 0.03 and error['max'] <= 0.15, error
    # Honest ellipses: most errors inside their 95 % ellipsoid (179 fixes: 0.91 here).
    assert 0.85 <= s['coverage_95'] <= 1.0, s['coverage_95']
