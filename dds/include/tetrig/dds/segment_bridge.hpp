// SegmentBridge: the DDS thread of one performer (docs/dds.md). It follows a shared-memory
// segment and writes each new frame to DDS (FramePublisher), off the solver thread: the solver
// thread stays allocation-free and lock-free (dds_write allocates and locks inside Cyclone).
//
// With the in-process ShmPublisher (tetrig run --dds) the thread sleeps in
// ShmPublisher::waitForCommit and wakes on each commit; without one it opens the segment by name
// and polls it. Either way it reads the newest frame through tetrig_shm.h (the seqlock reader:
// never torn) and writes it; a frame committed while the previous one was being written is
// skipped in favour of the newest (counted). The static data is written once, at start.
// It stops by stop(), or by itself when a segment opened by name is stopped, replaced or its
// producer dies (stats().end says which).
#pragma once

#include "tetrig/dds/frame_publisher.hpp"

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

namespace tetrig {
class ShmPublisher;
}

namespace tetrig::dds {

struct SegmentBridgeOptions {
  DdsOptions dds;
  bool normals = true;                   // send the segment's normals when it has them
  bool markers = true;                   // send the marker block when the segment has it
  std::int64_t poll_ns = 1'000'000;      // without an in-process publisher: the polling period
  std::int64_t wait_slice_ns = 50'000'000;  // longest sleep between checks of the stop flag
};

struct SegmentBridgeStats {
  std::uint64_t frames_written = 0;
  std::uint64_t frames_skipped = 0;  // committed but superseded before the bridge read them (gaps after the first frame written)
  std::uint64_t write_errors = 0;    // dds_write failed
  std::uint64_t read_busy = 0;       // the segment reader was lapped on every attempt (frame retried)
};

class SegmentBridge {
 public:
  // Opens the segment (`publisher`'s own mapping when given, else by name), creates the DDS
  // entities for `topic_base` (topicBaseName()), writes the static data and starts the thread.
  // Throws DdsError (DDS set-up, or a segment that cannot be opened, in one line). With
  // `publisher`, stop() (or the destructor) must come before the publisher is destroyed: the
  // thread reads its mapping.
  SegmentBridge(std::string segment_name, std::string topic_base, const ShmPublisher* publisher, const SegmentBridgeOptions& options);
  ~SegmentBridge();  // stop()
  SegmentBridge(const SegmentBridge&) = delete;
  SegmentBridge& operator=(const SegmentBridge&) = delete;

  // Asks the thread to stop, wakes it and joins it (idempotent). The DDS writers are deleted with
  // the bridge, so readers see the publisher leave.
  void stop();
  [[nodiscard]] SegmentBridgeStats stats() const noexcept;
  // Why the thread ended: "" while running, "stopped" (stop()), or the segment's fate.
  [[nodiscard]] std::string end() const;
  [[nodiscard]] const std::string& topicBase() const noexcept { return publisher_->base(); }
  [[nodiscard]] int matchedReaders() const noexcept { return publisher_->matchedFrameReaders(); }

 private:
  struct Segment;
  void run();
  void writeNewest(std::uint64_t& last);  // the segment's newest frame to DDS, if newer than `last` (bridge thread)

  std::string segment_name_;
  const ShmPublisher* shm_;
  SegmentBridgeOptions options_;
  std::unique_ptr<Segment> segment_;
  std::unique_ptr<FramePublisher> publisher_;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> written_{0}, skipped_{0}, errors_{0}, busy_{0};
  std::atomic<int> end_{0};  // 0 running, 1 stopped, 2 segment stopped, 3 producer died, 4 replaced or gone
  std::thread thread_;
};

}  // namespace tetrig::dds
