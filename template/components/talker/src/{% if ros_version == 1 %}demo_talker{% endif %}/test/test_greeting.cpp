// Unit tests of the talker's messages (run by `invoke test`, inside the component's image).
#include <gtest/gtest.h>

#include "demo_talker/greeting.h"

TEST(Greeting, CountsFromTheGivenNumber)
{
  EXPECT_EQ(demo_talker::greeting(1), "hello from talker #1");
  EXPECT_EQ(demo_talker::greeting(42), "hello from talker #42");
}

TEST(Greeting, DiffersFromOneMessageToTheNext)
{
  EXPECT_NE(demo_talker::greeting(1), demo_talker::greeting(2));
}

int main(int argc, char ** argv)
{
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
