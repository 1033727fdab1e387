"""`run_jobs`: the one pool loop under shards, closed-loop runs, tables, planner labels and mesh wrapping."""

import functools
import operator
import time

import pytest

from drake_grasp.datasets.shards import JobFailure, run_jobs

INVERSE = functools.partial(operator.truediv, 1.0)  # fails on 0 with ZeroDivisionError, in a worker process


def test_every_job_is_yielded_with_its_result_and_a_failed_one_ends_them_or_is_handed_on():
    assert dict(run_jobs(INVERSE, [1, 2, 4], workers=2)) == {1: 1.0, 2: 0.5, 4: 0.25}
    with pytest.raises(RuntimeError, match="job 0 failed: ZeroDivisionError"):
        list(run_jobs(INVERSE, [1, 0, 4], workers=2))
    results = dict(run_jobs(INVERSE, [1, 0, 4], workers=2, keep_going=True))
    assert results[1] == 1.0 and results[4] == 0.25
    assert isinstance(results[0], JobFailure) and isinstance(results[0].error, ZeroDivisionError)
    with pytest.raises(ValueError, match="invalid literal"):  # bad input ends every job, as it is
        list(run_jobs(int, ["1", "x", "3"], workers=2, keep_going=True))


def test_poll_runs_while_jobs_run_and_stopping_early_does_not_wait_for_the_jobs_in_flight():
    polls = []
    assert list(run_jobs(time.sleep, [1.5], workers=1, poll=lambda: polls.append(1))) == [(1.5, None)]
    assert len(polls) >= 3  # every half second while the job sleeps, and once more when it ends

    results = run_jobs(time.sleep, [0.1, 60, 60], workers=2)
    assert next(results) == (0.1, None)
    start = time.perf_counter()
    results.close()  # the two minute-long jobs (one in flight, one queued) are dropped
    assert time.perf_counter() - start < 20
