// Publish demo_msgs/Greeting "hello from talker #N" on /chatter every 0.5 s.
#include <ros/ros.h>

#include <demo_msgs/Greeting.h>

#include "demo_talker/greeting.h"

int main(int argc, char ** argv)
{
  ros::init(argc, argv, "talker");
  ros::NodeHandle node;
  ros::Publisher publisher = node.advertise<demo_msgs::Greeting>("chatter", 10);
  ros::Rate rate(2.0);
  std::uint32_t count = 0;
  while (ros::ok()) {
    demo_msgs::Greeting msg;
    msg.count = ++count;
    msg.text = demo_talker::greeting(msg.count);
    publisher.publish(msg);
    ROS_INFO("Publishing: %s", msg.text.c_str());
    ros::spinOnce();
    rate.sleep();
  }
  return 0;
}
