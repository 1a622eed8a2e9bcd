// SegmentBridge (segment_bridge.hpp): segment -> DDS on a thread of its own.
#include "tetrig/dds/segment_bridge.hpp"

#include "tetrig/shm_publisher.hpp"
#include "tetrig_shm.h"

#include <chrono>
#include <vector>

namespace tetrig::dds {

struct SegmentBridge::Segment {
  TetrigShmReader reader{};
  bool opened_by_name = false;
  bool has_normals = false;
  bool has_markers = false;
  std::vector<float> positions, normals, marker_positions;
  std::vector<std::uint8_t> marker_states;
  ~Segment() {
    if (opened_by_name) tetrig_shm_close(&reader);
  }
};

SegmentBridge::SegmentBridge(std::string segment_name, std::string topic_base, const ShmPublisher* publisher,
                             const SegmentBridgeOptions& options)
    : segment_name_(std::move(segment_name)), shm_(publisher), options_(options), segment_(std::make_unique<Segment>()) {
  Segment& s = *segment_;
  if (shm_ != nullptr) {
    const int rc = tetrig_shm_attach(&s.reader, shm_->segmentData(), shm_->segmentSize());
    if (rc != TETRIG_SHM_OK) throw DdsError("DDS bridge: segment " + segment_name_ + ": " + tetrig_shm_status_string(rc));
  } else {
    const std::string name = !segment_name_.empty() && segment_name_.front() == '/' ? segment_name_ : "/" + segment_name_;
    const int rc = tetrig_shm_open(&s.reader, name.c_str());
    if (rc != TETRIG_SHM_OK) throw DdsError("DDS bridge: segment " + name + ": " + tetrig_shm_status_string(rc));
    s.opened_by_name = true;
  }
  const std::uint32_t vertices = tetrig_shm_vertex_count(&s.reader);
  const std::uint32_t markers = tetrig_shm_marker_count(&s.reader);
  s.has_normals = options_.normals && tetrig_shm_has_normals(&s.reader);
  s.has_markers = options_.markers && tetrig_shm_has_marker_positions(&s.reader);
  s.positions.resize(3 * static_cast<std::size_t>(vertices));
  if (s.has_normals) s.normals.resize(3 * static_cast<std::size_t>(vertices));
  if (s.has_markers) {
    s.marker_positions.resize(3 * static_cast<std::size_t>(markers));
    s.marker_states.resize(markers);
  }

  publisher_ = std::make_unique<FramePublisher>(topic_base, options_.dds);
  // Static data, from the reader's checked copies.
  std::vector<std::uint32_t> triangles(3 * static_cast<std::size_t>(tetrig_shm_triangle_count(&s.reader)));
  if (!triangles.empty() && tetrig_shm_copy_triangles(&s.reader, triangles.data(), triangles.size()) != TETRIG_SHM_OK)
    throw DdsError("DDS bridge: segment " + segment_name_ + ": its triangles do not read back");
  const float* rest = tetrig_shm_rest_positions(&s.reader);
  std::vector<float> rest_positions(rest, rest + s.positions.size());
  std::vector<char> name_buf(static_cast<std::size_t>(s.reader.header_copy.rig_name_length) + 1);
  tetrig_shm_copy_rig_name(&s.reader, name_buf.data(), name_buf.size());
  std::vector<std::string> labels;
  for (std::uint32_t k = 0; k < markers; ++k) {
    char label[256];
    tetrig_shm_copy_marker_label(&s.reader, k, label, sizeof label);
    labels.emplace_back(label);
  }
  StaticView view;
  view.instance_id = s.reader.instance_id;
  view.rig_name = name_buf.data();
  view.vertex_count = vertices;
  view.triangles = triangles;
  view.rest_positions = rest_positions;
  view.marker_labels = labels;
  view.has_normals = s.has_normals;
  publisher_->publishStatic(view);
  thread_ = std::thread([this] { run(); });
}

SegmentBridge::~SegmentBridge() { stop(); }

void SegmentBridge::stop() {
  stop_.store(true, std::memory_order_seq_cst);
  // Once joined, the publisher it followed may be gone (tetrig run stops the bridge, then destroys
  // the segment, then the bridge): a second stop() touches nothing.
  if (thread_.joinable()) {
    if (shm_ != nullptr) shm_->wakeCommitWaiters();
    thread_.join();
  }
  int expected = 0;
  end_.compare_exchange_strong(expected, 1);
}

SegmentBridgeStats SegmentBridge::stats() const noexcept {
  SegmentBridgeStats s;
  s.frames_written = written_.load(std::memory_order_relaxed);
  s.frames_skipped = skipped_.load(std::memory_order_relaxed);
  s.write_errors = errors_.load(std::memory_order_relaxed);
  s.read_busy = busy_.load(std::memory_order_relaxed);
  return s;
}

std::string SegmentBridge::end() const {
  switch (end_.load(std::memory_order_acquire)) {
    case 0: return "";
    case 1: return "stopped";
    case 2: return "the segment's producer stopped";
    case 3: return "the segment's producer died";
    default: return "the segment was replaced or removed";
  }
}

void SegmentBridge::run() {
  Segment& s = *segment_;
  // Last frame id written (or skipped). Frames before the bridge started are not skipped ones: it
  // starts from the segment's newest (written at once), so written + skipped counts every frame
  // committed since.
  const std::uint64_t newest_at_start = tetrig_shm_latest_frame_id(&s.reader);
  std::uint64_t last = newest_at_start > 0 ? newest_at_start - 1 : 0;
  auto last_check = std::chrono::steady_clock::now();
  while (!stop_.load(std::memory_order_acquire)) {
    bool fresh;
    if (shm_ != nullptr) {
      fresh = shm_->waitForCommit(last, options_.wait_slice_ns);
    } else {
      fresh = tetrig_shm_latest_frame_id(&s.reader) > last;
      if (!fresh) {
        // By name: whether the producer is still there, every 20 ms while no frame comes.
        const auto now = std::chrono::steady_clock::now();
        if (now - last_check >= std::chrono::milliseconds(20)) {
          last_check = now;
          const int status = tetrig_shm_producer_status(&s.reader, INT64_MAX);
          int why = 0;
          if (status == TETRIG_SHM_PRODUCER_STOPPED) why = 2;
          else if (status == TETRIG_SHM_PRODUCER_DEAD) why = 3;
          else if (tetrig_shm_name_status(&s.reader) != TETRIG_SHM_NAME_SAME) why = 4;
          if (why != 0 && tetrig_shm_latest_frame_id(&s.reader) <= last) {
            end_.store(why, std::memory_order_release);
            return;
          }
        }
        std::this_thread::sleep_for(std::chrono::nanoseconds(options_.poll_ns));
        continue;
      }
    }
    if (!fresh || stop_.load(std::memory_order_acquire)) continue;
    writeNewest(last);
  }
  // Stopped (the run ends): the newest frame the segment holds goes out too, so that a subscriber's
  // last frame is the run's last (a read that meets the writer mid-copy is tried again).
  for (int attempt = 0; attempt < 8 && tetrig_shm_latest_frame_id(&s.reader) > last; ++attempt) writeNewest(last);
}

void SegmentBridge::writeNewest(std::uint64_t& last) {
  Segment& s = *segment_;
  TetrigShmFrameInfo info{};
  const int rc = s.has_markers
                     ? tetrig_shm_read_latest_markers(&s.reader, s.positions.data(), s.positions.size(),
                                                      s.has_normals ? s.normals.data() : nullptr, s.normals.size(),
                                                      s.marker_positions.data(), s.marker_positions.size(), s.marker_states.data(),
                                                      s.marker_states.size(), &info)
                     : tetrig_shm_read_latest(&s.reader, s.positions.data(), s.positions.size(),
                                              s.has_normals ? s.normals.data() : nullptr, s.normals.size(), &info);
  if (rc == TETRIG_SHM_BUSY) {
    busy_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (rc != TETRIG_SHM_OK || info.frame_id <= last) return;
  if (info.frame_id > last + 1) skipped_.fetch_add(info.frame_id - last - 1, std::memory_order_relaxed);
  last = info.frame_id;
  FrameView frame;
  frame.instance_id = s.reader.instance_id;
  frame.frame_id = info.frame_id;
  frame.source_frame = info.source_frame;
  frame.device_ns = info.device_ns;
  frame.receive_ns = info.receive_ns;
  frame.publish_ns = info.publish_ns;
  frame.flags = info.flags;
  frame.iterations = info.iterations;
  frame.occluded_markers = info.occluded_markers;
  frame.producer_state = static_cast<std::uint8_t>(tetrig_shm_state(&s.reader));
  frame.positions = s.positions;
  frame.normals = s.normals;
  frame.marker_positions = s.marker_positions;
  frame.marker_states = s.marker_states;
  if (publisher_->writeFrame(frame) != 0) {
    errors_.fetch_add(1, std::memory_order_relaxed);
  } else {
    written_.fetch_add(1, std::memory_order_relaxed);
  }
}

}  // namespace tetrig::dds
