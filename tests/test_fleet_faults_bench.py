"""bench/fleet_faults.py's pure part: the fault tests' lines turned into the performance page's rows."""

from __future__ import annotations

from bench_scripts import load

fleet_faults = load("fleet_faults")


def test_each_fault_gives_its_robots_left_and_its_time_with_what_was_measured_beside() -> None:
    lines = [{"fault": "manager restarted mid-rollout", "left": 1, "robots": 2, "healthy": 99.0},
             {"fault": "registry down during a wave", "left": 0, "robots": 4, "healthy": 8.6},
             {"fault": "manager restarted mid-rollout", "left": 0, "robots": 2, "healthy": 41.2, "manager_down": 9.5,
              "finished_after_manager_back": 20.1}]  # the last line of a fault is its run's
    rows = fleet_faults.figures(lines)
    assert [(f.label, f.value, f.met) for f in rows] == [
        ("registry down during a wave: robots left without a healthy release", 0, True),
        ("registry down during a wave: healthy fleet after", 8.6, None),
        ("manager restarted mid-rollout: robots left without a healthy release", 0, True),
        ("manager restarted mid-rollout: healthy fleet after", 41.2, None)]
    assert rows[3].detail == ("from the first rollout's start to the end of the one run again; the manager down "
                              "9.5 s; finished 20.1 s after the manager answered again")
    assert rows[0].detail == "of 4"


def test_a_robot_left_without_a_healthy_release_misses_the_goal() -> None:
    (left, _) = fleet_faults.figures([{"fault": "robot host power cut mid-update", "left": 1, "robots": 2,
                                       "healthy": 60.0}])
    assert (left.value, left.goal, left.met) == (1, "0", False)
