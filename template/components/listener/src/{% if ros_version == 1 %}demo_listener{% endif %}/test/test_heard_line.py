"""Unit tests of what the listener logs (run by `invoke test`, inside the component's image)."""

from demo_msgs.msg import Greeting

from demo_listener.listener import heard_line


def test_heard_line_quotes_the_message_text():
    assert heard_line(Greeting(text="hello from talker #3", count=3)) == "I heard: hello from talker #3"


def test_heard_line_of_an_empty_message():
    assert heard_line(Greeting()) == "I heard: "
