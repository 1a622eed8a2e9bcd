// The memory a frame reads, as byte ranges: what FrameLoop reads once just before a frame is due so
// that the frame finds it in the caches (tetrig/frame_loop.hpp, FrameLoopOptions::spin_before_frame_ns).
// Private to the runtime.
#pragma once

#include <cstddef>
#include <span>

namespace tetrig {

// Appends container c's elements as one range at out[count] (left out when out is full; an empty
// container adds nothing) and returns the new count. No allocation.
template <class Container>
std::size_t appendWorkingSet(std::span<std::span<const std::byte>> out, std::size_t count, const Container& c) noexcept {
  if (c.empty()) return count;
  if (count < out.size()) out[count] = std::as_bytes(std::span(c.data(), c.size()));
  return count + 1;
}

}  // namespace tetrig
