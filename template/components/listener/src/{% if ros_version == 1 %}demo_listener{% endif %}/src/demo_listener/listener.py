"""Log every demo_msgs/Greeting heard on /chatter as "I heard: <text>"."""

import rospy

from demo_msgs.msg import Greeting


def heard_line(msg):
    """The line logged for a message heard on /chatter."""
    return "I heard: %s" % msg.text


def heard(msg):
    """Log one message (rospy.loginfo: on stdout, and on /rosout)."""
    rospy.loginfo(heard_line(msg))


def main():
    """Entry point of `rosrun demo_listener listener`."""
    rospy.init_node("listener")
    rospy.Subscriber("chatter", Greeting, heard, queue_size=10)
    rospy.spin()
