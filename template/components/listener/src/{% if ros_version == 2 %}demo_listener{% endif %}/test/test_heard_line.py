"""Unit tests of what the listener prints (run by `invoke test`, inside the component's image)."""

from std_msgs.msg import String

from demo_listener.listener import heard_line


def test_heard_line_quotes_the_message_text() -> None:
    assert heard_line(String(data="hello from talker #3")) == "I heard: hello from talker #3"


def test_heard_line_of_an_empty_message() -> None:
    assert heard_line(String()) == "I heard: "
