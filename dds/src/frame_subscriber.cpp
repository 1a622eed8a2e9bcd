// The reader of tetrig's two DDS topics (frame_subscriber.hpp, docs/dds.md) on Cyclone's C API:
// one waitset over both readers (data available, and the frame reader's liveliness changes).
#include "tetrig/dds/frame_subscriber.hpp"

#include "dds_common.hpp"
#include "tetrig_frames.h"

#include <time.h>

#include <cmath>

namespace tetrig::dds {

std::int64_t monotonicNs() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::size_t ReceivedFrame::payloadBytes() const noexcept {
  // Encapsulation header 4, three u64 and four i64 (56), u32 + i32 (8), u16 + u8 + 1 pad (4),
  // then four sequences: a u32 length each and their elements.
  return 72 + 16 + 4 * (positions.size() + normals.size() + marker_positions.size()) + marker_states.size();
}

namespace {

template <typename T, typename Seq>
std::vector<T> copySeq(const Seq& seq) {
  if (seq._buffer == nullptr || seq._length == 0) return {};
  return std::vector<T>(seq._buffer, seq._buffer + seq._length);
}

bool allFinite(const std::vector<float>& v) {
  for (const float x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

}  // namespace

struct FrameSubscriber::Impl {
  dds_entity_t participant = 0, frame_reader = 0, static_reader = 0, waitset = 0;
  ~Impl() {
    if (participant > 0) dds_delete(participant);
  }
};

FrameSubscriber::FrameSubscriber(std::string_view base, const DdsOptions& options) : impl_(std::make_unique<Impl>()) {
  const std::string who = "DDS subscriber for '" + std::string(base) + "'";
  impl_->participant = detail::createParticipant(options, who);
  const std::string frame_name = frameTopicName(base), static_name = staticTopicName(base);
  const dds_entity_t frame_topic = dds_create_topic(impl_->participant, &tetrig_dds_Frame_desc, frame_name.c_str(), nullptr, nullptr);
  if (frame_topic < 0) throw DdsError(who + ": topic " + frame_name + ": " + detail::retcodeText(frame_topic));
  const dds_entity_t static_topic = dds_create_topic(impl_->participant, &tetrig_dds_Static_desc, static_name.c_str(), nullptr, nullptr);
  if (static_topic < 0) throw DdsError(who + ": topic " + static_name + ": " + detail::retcodeText(static_topic));
  const detail::Qos frame_qos, static_qos;
  detail::setFrameQos(frame_qos, options.liveliness_lease_ns);
  detail::setStaticQos(static_qos, options.liveliness_lease_ns);
  impl_->frame_reader = dds_create_reader(impl_->participant, frame_topic, frame_qos.get(), nullptr);
  if (impl_->frame_reader < 0) throw DdsError(who + ": frame reader: " + detail::retcodeText(impl_->frame_reader));
  impl_->static_reader = dds_create_reader(impl_->participant, static_topic, static_qos.get(), nullptr);
  if (impl_->static_reader < 0) throw DdsError(who + ": static reader: " + detail::retcodeText(impl_->static_reader));
  dds_set_status_mask(impl_->frame_reader, DDS_DATA_AVAILABLE_STATUS | DDS_LIVELINESS_CHANGED_STATUS);
  dds_set_status_mask(impl_->static_reader, DDS_DATA_AVAILABLE_STATUS);
  impl_->waitset = dds_create_waitset(impl_->participant);
  if (impl_->waitset < 0) throw DdsError(who + ": waitset: " + detail::retcodeText(impl_->waitset));
  dds_return_t rc = dds_waitset_attach(impl_->waitset, impl_->frame_reader, 0);
  if (rc >= 0) rc = dds_waitset_attach(impl_->waitset, impl_->static_reader, 1);
  if (rc < 0) throw DdsError(who + ": waitset attach: " + detail::retcodeText(rc));
}

FrameSubscriber::~FrameSubscriber() = default;

std::size_t FrameSubscriber::poll(std::int64_t timeout_ns, std::vector<SubscriberEvent>& events) {
  const std::size_t before = events.size();
  dds_waitset_wait(impl_->waitset, nullptr, 0, timeout_ns);
  // Liveliness: reading the status resets its change counts.
  dds_liveliness_changed_status_t live{};
  if (dds_get_liveliness_changed_status(impl_->frame_reader, &live) >= 0 &&
      (live.alive_count_change != 0 || live.not_alive_count_change != 0)) {
    alive_ = static_cast<int>(live.alive_count);
    SubscriberEvent e;
    e.alive_count = alive_;
    if (live.alive_count_change > 0) {
      e.kind = SubscriberEvent::kPublisherAlive;
    } else if (live.not_alive_count_change > 0) {
      e.kind = SubscriberEvent::kPublisherLost;
    } else {
      e.kind = SubscriberEvent::kPublisherLeft;
    }
    events.push_back(std::move(e));
  }
  constexpr int kBatch = 16;
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  for (;;) {
    const dds_return_t n = dds_take(impl_->static_reader, samples, infos, kBatch, kBatch);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* s = static_cast<const tetrig_dds_Static*>(samples[i]);
      SubscriberEvent e;
      e.kind = SubscriberEvent::kStatic;
      e.static_data.instance_id = s->instance_id;
      e.static_data.rig_name = s->rig_name != nullptr ? s->rig_name : "";
      e.static_data.vertex_count = s->vertex_count;
      e.static_data.triangles = copySeq<std::uint32_t>(s->triangles);
      e.static_data.rest_positions = copySeq<float>(s->rest_positions);
      for (std::uint32_t k = 0; k < s->marker_labels._length && s->marker_labels._buffer != nullptr; ++k)
        e.static_data.marker_labels.emplace_back(s->marker_labels._buffer[k] != nullptr ? s->marker_labels._buffer[k] : "");
      e.static_data.has_normals = s->has_normals;
      events.push_back(std::move(e));
    }
    dds_return_loan(impl_->static_reader, samples, n);
  }
  for (;;) {
    const dds_return_t n = dds_take(impl_->frame_reader, samples, infos, kBatch, kBatch);
    if (n <= 0) break;
    const std::int64_t seen = monotonicNs();
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* s = static_cast<const tetrig_dds_Frame*>(samples[i]);
      SubscriberEvent e;
      e.kind = SubscriberEvent::kFrame;
      ReceivedFrame& f = e.frame;
      f.instance_id = s->instance_id;
      f.frame_id = s->frame_id;
      f.source_frame = s->source_frame;
      f.device_ns = s->device_ns;
      f.receive_ns = s->receive_ns;
      f.publish_ns = s->publish_ns;
      f.write_ns = s->write_ns;
      f.seen_ns = seen;
      f.flags = s->flags;
      f.iterations = s->iterations;
      f.occluded_markers = s->occluded_markers;
      f.producer_state = s->producer_state;
      f.positions = copySeq<float>(s->positions);
      f.normals = copySeq<float>(s->normals);
      f.marker_positions = copySeq<float>(s->marker_positions);
      f.marker_states = copySeq<std::uint8_t>(s->marker_states);
      events.push_back(std::move(e));
    }
    dds_return_loan(impl_->frame_reader, samples, n);
  }
  return events.size() - before;
}

bool FrameChecker::acceptStatic(const ReceivedStatic& d, std::string& why) {
  const std::uint64_t v = d.vertex_count;
  if (v == 0) {
    why = "static data refused: vertex count 0";
  } else if (d.rest_positions.size() != 3 * v) {
    why = "static data refused: " + std::to_string(d.rest_positions.size()) + " rest-position floats for " + std::to_string(v) +
          " vertices (need " + std::to_string(3 * v) + ")";
  } else if (d.triangles.size() % 3 != 0) {
    why = "static data refused: " + std::to_string(d.triangles.size()) + " triangle indices (not a multiple of 3)";
  } else if (!allFinite(d.rest_positions)) {
    why = "static data refused: a rest position is not finite";
  } else {
    why.clear();
    for (const std::uint32_t t : d.triangles) {
      if (t >= v) {
        why = "static data refused: triangle index " + std::to_string(t) + " >= vertex count " + std::to_string(v);
        break;
      }
    }
    if (why.empty()) {
      statics_[d.instance_id] = d;
      return true;
    }
  }
  return false;
}

const ReceivedStatic* FrameChecker::staticFor(std::uint64_t instance_id) const {
  const auto it = statics_.find(instance_id);
  return it == statics_.end() ? nullptr : &it->second;
}

FrameChecker::Verdict FrameChecker::checkFrame(const ReceivedFrame& f, std::string& why) {
  const ReceivedStatic* s = staticFor(f.instance_id);
  const std::string id = "frame " + std::to_string(f.frame_id) + " refused: ";
  if (s == nullptr) {
    why = "frame " + std::to_string(f.frame_id) + " of an instance without static data yet";
    return Verdict::kWaitingForStatic;
  }
  const std::size_t need = 3 * static_cast<std::size_t>(s->vertex_count);
  const std::size_t markers = s->marker_labels.size();
  std::uint64_t& last = last_frame_id_[f.instance_id];
  if (f.frame_id == 0) {
    why = id + "frame id 0";
  } else if (f.frame_id <= last) {
    why = id + "frame id not above the last one accepted (" + std::to_string(last) + ")";
  } else if (f.positions.size() != need) {
    why = id + std::to_string(f.positions.size()) + " position floats for " + std::to_string(s->vertex_count) + " vertices (need " +
          std::to_string(need) + ")";
  } else if (!f.normals.empty() && f.normals.size() != need) {
    why = id + std::to_string(f.normals.size()) + " normal floats (need 0 or " + std::to_string(need) + ")";
  } else if (!f.marker_positions.empty() && f.marker_positions.size() != 3 * markers) {
    why = id + std::to_string(f.marker_positions.size()) + " marker-position floats for " + std::to_string(markers) + " markers";
  } else if (!f.marker_states.empty() && f.marker_states.size() != markers) {
    why = id + std::to_string(f.marker_states.size()) + " marker states for " + std::to_string(markers) + " markers";
  } else if (!allFinite(f.positions) || !allFinite(f.normals) || !allFinite(f.marker_positions)) {
    why = id + "a non-finite value";
  } else {
    why.clear();
    last = f.frame_id;
    return Verdict::kAccepted;
  }
  return Verdict::kRefused;
}

}  // namespace tetrig::dds
