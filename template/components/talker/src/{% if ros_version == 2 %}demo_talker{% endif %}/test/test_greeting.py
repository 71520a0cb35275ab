"""Unit tests of the talker's messages (run by `invoke test`, inside the component's image)."""

from demo_talker.talker import greeting


def test_greeting_counts_from_the_given_number() -> None:
    assert greeting(1) == "hello from talker #1"
    assert greeting(42) == "hello from talker #42"


def test_greetings_differ_from_one_message_to_the_next() -> None:
    assert greeting(1) != greeting(2)
