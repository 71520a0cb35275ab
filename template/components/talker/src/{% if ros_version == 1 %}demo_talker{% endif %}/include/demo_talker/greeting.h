// The text of the talker's messages (header-only, so that the unit test needs no library).
#pragma once

#include <cstdint>
#include <string>

namespace demo_talker
{

/// The text of the ``count``-th message: "hello from talker #<count>".
inline std::string greeting(std::uint32_t count)
{
  return "hello from talker #" + std::to_string(count);
}

}  // namespace demo_talker
