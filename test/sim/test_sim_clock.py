"""The sim's slowed clock (its real-time factor)."""

from pattern_locator.sim.sim_clock import ScaledClock
import pytest


class ManualClock:
    """A base clock the test sets."""

    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_the_clock_runs_at_its_rate_from_its_origin():
    base = ManualClock(100.0)
    clock = ScaledClock(0.25, base)
    assert clock() == 100.0 and clock.origin == 100.0
    base.t = 108.0
    assert clock() == pytest.approx(102.0)
    assert clock.wall_s(0.1) == pytest.approx(0.4)
    # At 1 it is the base clock.
    same = ScaledClock(1.0, base)
    base.t = 150.0
    assert same() == 150.0


@pytest.mark.parametrize('rate', [0.0, -0.5, 1.5, float('nan'), float('inf')])
def test_a_rate_outside_zero_to_one_is_refused(rate):
    with pytest.raises(ValueError, match='real-time factor'):
        ScaledClock(rate)
