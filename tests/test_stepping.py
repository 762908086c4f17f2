"""Load stepping's grid: after a cut-back the steps come back onto the run's grid of dt_max."""

import pytest

from fenicsx_drape.fe.stepping import StepReport, run


class Fake:
    """A problem whose step fails when it is longer than ``limit`` s before ``hard_until`` s.

    ``iterations(t0, t)``: the Newton iterations of the step from t0 to t (default 3, easy).
    """

    def __init__(self, limit, hard_until, iterations=lambda t0, t: 3):
        self.t, self.comm = 0.0, None
        self.limit, self.hard_until, self.iterations = limit, hard_until, iterations

    def step(self, t):
        t0, ok = self.t, t - self.t <= self.limit or self.t >= self.hard_until
        if ok:
            self.t = t
        return StepReport(t, t - t0, ok, self.iterations(t0, t), "ok" if ok else "DIVERGED")


def accepted(problem, t_end, dt, **kw):
    return [round(s.time_s, 9) for s in run(problem, t_end, dt, **kw).accepted]


def test_the_steps_after_a_cut_back_land_on_the_uncut_runs_steps():
    # The first step is cut to 0.25 s; growing by 1.5 would go on from 0.25 + 0.375 =
    # 0.625 s, off every later step of a run that was not cut.
    times = accepted(Fake(limit=0.3, hard_until=0.5), 2.0, 0.5)
    assert times == [0.25, 0.5, 1.0, 1.5, 2.0]
    assert accepted(Fake(limit=1.0, hard_until=0.0), 2.0, 0.5) == [0.5, 1.0, 1.5, 2.0]


def test_a_hard_step_back_to_the_grid_does_not_shorten_the_next():
    # Cut to 0.25 s, grown to 0.375 s and shortened to 0.25 s to reach the grid at 0.5 s,
    # where the step is hard: the next is 0.375 s again, not the shortened 0.25 s.
    problem = Fake(limit=0.3, hard_until=0.5, iterations=lambda t0, t: 20 if t == 0.5 else 3)
    times = accepted(problem, 2.0, 0.5, easy_iterations=5)
    assert times == [0.25, 0.5, 0.875, 1.0, 1.5, 2.0]


def test_a_last_step_just_past_the_grid_is_taken_whole():
    # t_end 0.5 % past a grid point: no sliver of 0.0025 s at the end.
    assert accepted(Fake(limit=1.0, hard_until=0.0), 1.0025, 0.5) == [0.5, pytest.approx(1.0025)]
