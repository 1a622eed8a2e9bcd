// tetrig's frames over Eclipse Cyclone DDS (docs/dds.md): the topic names, the QoS, a writer of
// the two topics (FramePublisher) and a reader of them (FrameSubscriber, frame_subscriber.hpp).
//
// Topics, one pair per performer, named from the performer's segment name (topicBaseName):
//   tetrig/<base>/frame   type tetrig_dds::Frame   best effort, volatile, keep last 1
//   tetrig/<base>/static  type tetrig_dds::Static  reliable, transient local, keep last 1
// Both writers offer automatic liveliness with a lease (DdsOptions::liveliness_lease_ns): a
// publisher that dies without deleting its writers (SIGKILL, a crash, a cut link) is reported
// "not alive" to every reader once the lease has passed. The types are dds/idl/tetrig_frames.idl.
//
// Threads: a FramePublisher is used by one thread at a time (the DDS calls lock and allocate
// inside Cyclone: never from the solver thread; tetrig::dds::SegmentBridge runs it on its own).
// The Cyclone headers stay out of this header.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tetrig::dds {

// Thrown by constructors and set-up calls, with one line naming what failed and why.
class DdsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The base of the topic names for a segment name: the leading '/' dropped, '-' and '.' written
// as '_' (DDS topic names hold only letters, digits, '_' and '/'); e.g. "/tetrig-man" ->
// "tetrig_man". Throws DdsError for an empty name or any other character (named in the message).
std::string topicBaseName(std::string_view segment_name);
// "tetrig/<base>/frame" and "tetrig/<base>/static".
std::string frameTopicName(std::string_view base);
std::string staticTopicName(std::string_view base);

struct DdsOptions {
  // The DDS domain; -1: the domain of the Cyclone configuration (CYCLONEDDS_URI), else 0.
  int domain_id = -1;
  // Automatic liveliness lease of the writers (offered) and the readers (requested): a dead
  // publisher is reported within about this time (docs/dds.md, "Liveliness"). A reader that asks
  // for a shorter lease than a writer offers does not match it (DDS QoS rules): keep both equal.
  std::int64_t liveliness_lease_ns = 1'000'000'000;
};

// One live frame (tetrig_dds::Frame): spans point at the caller's buffers for the write's duration.
struct FrameView {
  std::uint64_t instance_id = 0;
  std::uint64_t frame_id = 0;
  std::uint64_t source_frame = 0;
  std::int64_t device_ns = 0;
  std::int64_t receive_ns = 0;
  std::int64_t publish_ns = 0;
  std::int64_t write_ns = 0;  // writeFrame() stamps it
  std::uint32_t flags = 0;
  std::int32_t iterations = 0;
  std::uint16_t occluded_markers = 0;
  std::uint8_t producer_state = 1;
  std::span<const float> positions;
  std::span<const float> normals;
  std::span<const float> marker_positions;
  std::span<const std::uint8_t> marker_states;
};

// The static data (tetrig_dds::Static).
struct StaticView {
  std::uint64_t instance_id = 0;
  std::string_view rig_name;
  std::uint32_t vertex_count = 0;
  std::span<const std::uint32_t> triangles;
  std::span<const float> rest_positions;
  std::span<const std::string> marker_labels;
  bool has_normals = false;
};

class FramePublisher {
 public:
  // Creates the participant, the two topics and their writers. `base`: topicBaseName()'s result.
  // Throws DdsError (no DDS domain, a bad configuration, a name DDS refuses).
  FramePublisher(std::string_view base, const DdsOptions& options);
  ~FramePublisher();  // deletes the writers: readers see the publisher leave (not a lost liveliness)
  FramePublisher(const FramePublisher&) = delete;
  FramePublisher& operator=(const FramePublisher&) = delete;

  // Writes the static data (reliable, kept for late readers). Throws DdsError when DDS refuses it.
  void publishStatic(const StaticView& data);
  // Writes one frame as given (nothing is checked: readers check), stamping frame.write_ns just
  // before the write. Returns 0, or Cyclone's negative return code.
  int writeFrame(FrameView& frame) noexcept;
  // Readers matched with the frame writer now.
  [[nodiscard]] int matchedFrameReaders() const noexcept;
  // Waits (polling every millisecond) until at least `count` frame readers are matched, at most
  // `timeout_ns`. Returns whether they are.
  bool waitForFrameReaders(int count, std::int64_t timeout_ns) const noexcept;
  [[nodiscard]] const std::string& base() const noexcept { return base_; }

 private:
  struct Impl;
  std::string base_;
  std::unique_ptr<Impl> impl_;
};

// Text of a Cyclone return code (dds_strretcode).
std::string ddsErrorText(int code);

}  // namespace tetrig::dds
