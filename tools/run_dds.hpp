// `tetrig run --dds` (docs/dds.md): the DDS bridge beside the segment, kept out of run.cpp so that
// the live path's structure and the DDS wiring change independently. Without --dds every member
// does nothing; in a build without DDS (TETRIG_DDS off) --dds is refused in one line.
#pragma once

#include "run.hpp"
#include "tetrig/shm_publisher.hpp"

#include <nlohmann/json.hpp>

#include <memory>

namespace tetrig::dds {
class SegmentBridge;
}

namespace tetrig::tools {

class RunDds {
 public:
  // With options.dds: the topic names from the segment's name (one pair per segment, so one
  // RunDds per performer's publisher), the static data written, the bridge thread started on
  // `publisher`. Throws std::runtime_error (one line) when DDS cannot start.
  RunDds(const RunOptions& options, const ShmPublisher& publisher);
  ~RunDds();
  RunDds(const RunDds&) = delete;
  RunDds& operator=(const RunDds&) = delete;

  void stop();                              // joins the bridge (before the segment goes)
  void printBanner() const;                 // "  publishing over DDS: ..." on stdout
  void printSummary() const;                // the summary line on stdout
  void addStats(nlohmann::json& j) const;   // the "dds" object of --stats-json

 private:
  std::unique_ptr<dds::SegmentBridge> bridge_;
};

}  // namespace tetrig::tools
