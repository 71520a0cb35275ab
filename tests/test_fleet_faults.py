"""The gate's reasons for faults on the fleet's side (pure): a robot that could not pull its release says so."""

from __future__ import annotations

from robocore.plan.gate_reasons import task_ended


def test_a_task_its_node_could_not_pull_says_so() -> None:
    assert task_ended("talker", "failed", 3, "task: non-zero exit (3)") == \
        "talker failed with code 3: task: non-zero exit (3) (restarting)"
    pulled = task_ended("talker", "rejected", 0, "No such image: reg:5000/p-talker@sha256:ab")  # as Swarm says it
    assert pulled == ("talker rejected: No such image: reg:5000/p-talker@sha256:ab (the robot could not pull the "
                      "image: is the registry up, and reachable from the robot?) (restarting)")
    assert "could not pull" not in task_ended("talker", "rejected", None, "invalid mount config")


def test_the_registrys_own_hint_is_said_once_in_place_of_the_generic_one() -> None:
    error = "No such image: reg:5000/p-talker@sha256:ab"
    told = task_ended("talker", "rejected", 0, error, "the robot could not pull it from reg:5000: log in")
    assert told == f"talker rejected: {error} (the robot could not pull it from reg:5000: log in) (restarting)"
