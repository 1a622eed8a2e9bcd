// The reader side of tetrig's DDS topics (docs/dds.md): FrameSubscriber takes frames and static
// data and reports the publishers' liveliness; FrameChecker refuses malformed samples. Used by
// tetrig-dds-cat and tetrig view --dds. Allocates freely (never on a real-time thread).
#pragma once

#include "tetrig/dds/frame_publisher.hpp"

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace tetrig::dds {

struct ReceivedFrame {
  std::uint64_t instance_id = 0, frame_id = 0, source_frame = 0;
  std::int64_t device_ns = 0, receive_ns = 0, publish_ns = 0, write_ns = 0;
  std::int64_t seen_ns = 0;  // CLOCK_MONOTONIC when this process took it
  std::uint32_t flags = 0;
  std::int32_t iterations = 0;
  std::uint16_t occluded_markers = 0;
  std::uint8_t producer_state = 0;
  std::vector<float> positions, normals, marker_positions;
  std::vector<std::uint8_t> marker_states;
  // Bytes of the sample's payload as serialized (XCDR1: fixed fields, 4-byte sequence lengths, elements).
  [[nodiscard]] std::size_t payloadBytes() const noexcept;
};

struct ReceivedStatic {
  std::uint64_t instance_id = 0;
  std::string rig_name;
  std::uint32_t vertex_count = 0;
  std::vector<std::uint32_t> triangles;
  std::vector<float> rest_positions;
  std::vector<std::string> marker_labels;
  bool has_normals = false;
};

// What FrameSubscriber::poll() found, in order.
struct SubscriberEvent {
  enum Kind {
    kFrame,             // `frame` holds a frame (not yet checked: FrameChecker)
    kStatic,            // `static_data` holds static data (not yet checked)
    kPublisherAlive,    // a frame writer became alive (a new or restarted publisher): alive_count
    kPublisherLost,     // a frame writer's liveliness lease passed (killed, hung, link cut): alive_count
    kPublisherLeft,     // a frame writer was deleted (a clean stop): alive_count
  } kind = kFrame;
  ReceivedFrame frame;
  ReceivedStatic static_data;
  int alive_count = 0;
};

class FrameSubscriber {
 public:
  // Creates the participant and the two readers (QoS matching the writers'). `base`:
  // topicBaseName()'s result. Throws DdsError.
  FrameSubscriber(std::string_view base, const DdsOptions& options);
  ~FrameSubscriber();
  FrameSubscriber(const FrameSubscriber&) = delete;
  FrameSubscriber& operator=(const FrameSubscriber&) = delete;

  // Waits up to `timeout_ns` for data or a liveliness change, then appends every event pending
  // (liveliness changes first, then static data, then frames) to `events`. Returns the number
  // appended (0 on timeout).
  std::size_t poll(std::int64_t timeout_ns, std::vector<SubscriberEvent>& events);
  // Frame writers alive now.
  [[nodiscard]] int alivePublishers() const noexcept { return alive_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int alive_ = 0;
};

// Refuses malformed samples: static data whose counts do not agree (triangles not in threes, an
// index out of range, rest positions not 3 x vertex count, non-finite values, no vertices), and
// frames whose arrays do not fit their instance's static data (positions != 3 x vertex count,
// normals or marker arrays of another length), with a non-finite value, frame id 0, or a frame id
// not above the last one accepted of that instance (going backwards or repeated). A frame of an
// instance whose static data has not come yet cannot be checked: kWaitingForStatic.
class FrameChecker {
 public:
  enum class Verdict { kAccepted, kRefused, kWaitingForStatic };
  // Checks static data; on success it becomes its instance's reference. `why` gets one line.
  bool acceptStatic(const ReceivedStatic& data, std::string& why);
  Verdict checkFrame(const ReceivedFrame& frame, std::string& why);
  // The accepted static data of `instance_id`, or nullptr.
  [[nodiscard]] const ReceivedStatic* staticFor(std::uint64_t instance_id) const;

 private:
  std::map<std::uint64_t, ReceivedStatic> statics_;
  std::map<std::uint64_t, std::uint64_t> last_frame_id_;
};

// CLOCK_MONOTONIC nanoseconds (the clock of every frame time but device_ns).
std::int64_t monotonicNs() noexcept;

}  // namespace tetrig::dds
