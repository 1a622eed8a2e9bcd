// The writer of tetrig's two DDS topics (frame_publisher.hpp, docs/dds.md) on Cyclone's C API.
#include "tetrig/dds/frame_publisher.hpp"

#include "dds_common.hpp"
#include "tetrig_frames.h"

#include <time.h>

#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

namespace tetrig::dds {

namespace {

std::int64_t nowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// A sequence that borrows the caller's buffer: the write serializes it, nothing is freed.
template <typename Seq, typename T>
void borrow(Seq& seq, std::span<const T> data) {
  seq._maximum = static_cast<std::uint32_t>(data.size());
  seq._length = static_cast<std::uint32_t>(data.size());
  seq._buffer = const_cast<T*>(data.data());
  seq._release = false;
}

}  // namespace

std::string topicBaseName(std::string_view segment_name) {
  std::string_view name = segment_name;
  if (!name.empty() && name.front() == '/') name.remove_prefix(1);
  if (name.empty()) throw DdsError("DDS topic name: the segment name is empty");
  std::string base;
  base.reserve(name.size());
  for (const char c : name) {
    const auto u = static_cast<unsigned char>(c);
    if ((u >= 'a' && u <= 'z') || (u >= 'A' && u <= 'Z') || (u >= '0' && u <= '9') || c == '_') {
      base += c;
    } else if (c == '-' || c == '.') {
      base += '_';
    } else {
      char shown[8];
      std::snprintf(shown, sizeof shown, u >= 0x20 && u < 0x7f ? "'%c'" : "\\x%02x", u);
      throw DdsError("DDS topic name: the segment name has a character DDS topic names cannot hold (" + std::string(shown) +
                     "): use letters, digits, '_', '-' or '.'");
    }
  }
  return base;
}

std::string frameTopicName(std::string_view base) { return "tetrig/" + std::string(base) + "/frame"; }
std::string staticTopicName(std::string_view base) { return "tetrig/" + std::string(base) + "/static"; }
std::string ddsErrorText(int code) { return dds_strretcode(code); }

struct FramePublisher::Impl {
  dds_entity_t participant = 0;
  dds_entity_t frame_topic = 0, static_topic = 0;
  dds_entity_t frame_writer = 0, static_writer = 0;
  ~Impl() {
    if (participant > 0) dds_delete(participant);  // deletes the topics and writers with it
  }
};

FramePublisher::FramePublisher(std::string_view base, const DdsOptions& options) : base_(base), impl_(std::make_unique<Impl>()) {
  const std::string who = "DDS publisher for '" + base_ + "'";
  impl_->participant = detail::createParticipant(options, who);
  const std::string frame_name = frameTopicName(base_), static_name = staticTopicName(base_);
  impl_->frame_topic = dds_create_topic(impl_->participant, &tetrig_dds_Frame_desc, frame_name.c_str(), nullptr, nullptr);
  if (impl_->frame_topic < 0) throw DdsError(who + ": topic " + frame_name + ": " + detail::retcodeText(impl_->frame_topic));
  impl_->static_topic = dds_create_topic(impl_->participant, &tetrig_dds_Static_desc, static_name.c_str(), nullptr, nullptr);
  if (impl_->static_topic < 0) throw DdsError(who + ": topic " + static_name + ": " + detail::retcodeText(impl_->static_topic));
  const detail::Qos frame_qos, static_qos;
  detail::setFrameQos(frame_qos, options.liveliness_lease_ns);
  detail::setStaticQos(static_qos, options.liveliness_lease_ns);
  impl_->frame_writer = dds_create_writer(impl_->participant, impl_->frame_topic, frame_qos.get(), nullptr);
  if (impl_->frame_writer < 0) throw DdsError(who + ": frame writer: " + detail::retcodeText(impl_->frame_writer));
  impl_->static_writer = dds_create_writer(impl_->participant, impl_->static_topic, static_qos.get(), nullptr);
  if (impl_->static_writer < 0) throw DdsError(who + ": static writer: " + detail::retcodeText(impl_->static_writer));
}

FramePublisher::~FramePublisher() = default;

void FramePublisher::publishStatic(const StaticView& data) {
  const std::string name(data.rig_name);
  std::vector<char*> labels;
  labels.reserve(data.marker_labels.size());
  for (const std::string& l : data.marker_labels) labels.push_back(const_cast<char*>(l.c_str()));
  tetrig_dds_Static sample{};
  sample.instance_id = data.instance_id;
  sample.rig_name = const_cast<char*>(name.c_str());
  sample.vertex_count = data.vertex_count;
  borrow(sample.triangles, data.triangles);
  borrow(sample.rest_positions, data.rest_positions);
  sample.marker_labels._maximum = static_cast<std::uint32_t>(labels.size());
  sample.marker_labels._length = static_cast<std::uint32_t>(labels.size());
  sample.marker_labels._buffer = labels.data();
  sample.marker_labels._release = false;
  sample.has_normals = data.has_normals;
  const dds_return_t rc = dds_write(impl_->static_writer, &sample);
  if (rc < 0) throw DdsError("DDS publisher for '" + base_ + "': static data not written: " + detail::retcodeText(rc));
}

int FramePublisher::writeFrame(FrameView& frame) noexcept {
  tetrig_dds_Frame sample{};
  sample.instance_id = frame.instance_id;
  sample.frame_id = frame.frame_id;
  sample.source_frame = frame.source_frame;
  sample.device_ns = frame.device_ns;
  sample.receive_ns = frame.receive_ns;
  sample.publish_ns = frame.publish_ns;
  sample.flags = frame.flags;
  sample.iterations = frame.iterations;
  sample.occluded_markers = frame.occluded_markers;
  sample.producer_state = frame.producer_state;
  borrow(sample.positions, frame.positions);
  borrow(sample.normals, frame.normals);
  borrow(sample.marker_positions, frame.marker_positions);
  borrow(sample.marker_states, frame.marker_states);
  frame.write_ns = nowNs();
  sample.write_ns = frame.write_ns;
  const dds_return_t rc = dds_write(impl_->frame_writer, &sample);
  return rc < 0 ? static_cast<int>(rc) : 0;
}

int FramePublisher::matchedFrameReaders() const noexcept {
  dds_publication_matched_status_t st{};
  if (dds_get_publication_matched_status(impl_->frame_writer, &st) < 0) return 0;
  return static_cast<int>(st.current_count);
}

bool FramePublisher::waitForFrameReaders(int count, std::int64_t timeout_ns) const noexcept {
  const std::int64_t end = nowNs() + timeout_ns;
  while (matchedFrameReaders() < count) {
    if (nowNs() >= end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return true;
}

}  // namespace tetrig::dds
