"""Stage timings (`refinenet.profiling`): recorded only inside a recording, summed per name, nested as OUTER/INNER."""

from __future__ import annotations

import time

from refinenet.profiling import recording, stage


def busy(seconds: float) -> None:
    """Spin for `seconds` of both wall and CPU time, so a busy machine (tests run in parallel) only stretches it."""
    wall, cpu = time.perf_counter() + seconds, time.process_time() + seconds
    while time.perf_counter() < wall or time.process_time() < cpu:
        pass


def test_stages_add_up_per_name_and_nest_under_their_outer_stage():
    with recording() as stages:
        for _ in range(3):
            with stage("outer"):
                busy(0.01)
                with stage("inner"):
                    busy(0.02)
        with stage("inner"):
            busy(0.01)
    assert list(stages) == ["outer/inner", "outer", "inner"]
    assert [stages[name]["calls"] for name in stages] == [3, 3, 1]
    assert 0.06 <= stages["outer/inner"]["wall_s"] < stages["outer"]["wall_s"]
    assert stages["outer"]["wall_s"] >= 0.09 and stages["outer"]["cpu_s"] >= 0.08
    assert 0.01 <= stages["inner"]["wall_s"] < stages["outer/inner"]["wall_s"]


def test_outside_a_recording_a_stage_records_nothing_and_a_recording_starts_empty():
    with stage("unseen"):
        pass
    with recording() as first:
        with stage("a"):
            with recording() as second:
                with stage("b"):
                    pass
    assert list(first) == ["a"] and list(second) == ["b"]
