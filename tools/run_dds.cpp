// `tetrig run --dds` (run_dds.hpp, docs/dds.md).
#include "run_dds.hpp"

#include <cstdio>
#include <stdexcept>
#include <string>

#if TETRIG_HAVE_DDS
#include "tetrig/dds/segment_bridge.hpp"
#else
namespace tetrig::dds {
class SegmentBridge {};  // never made in a build without DDS
}  // namespace tetrig::dds
#endif

namespace tetrig::tools {

#if TETRIG_HAVE_DDS

RunDds::RunDds(const RunOptions& options, const ShmPublisher& publisher) {
  if (!options.dds) return;
  try {
    const std::string base = dds::topicBaseName(publisher.name());  // per segment: one topic pair per performer
    dds::SegmentBridgeOptions bridge_options;
    bridge_options.normals = options.normals;
    bridge_ = std::make_unique<dds::SegmentBridge>(publisher.name(), base, &publisher, bridge_options);
  } catch (const dds::DdsError& e) {
    throw std::runtime_error(std::string("--dds: ") + e.what());
  }
}

RunDds::~RunDds() { stop(); }

void RunDds::stop() {
  if (bridge_) bridge_->stop();
}

void RunDds::printBanner() const {
  if (!bridge_) return;
  std::printf("  publishing over DDS too: topics %s and %s\n", dds::frameTopicName(bridge_->topicBase()).c_str(),
              dds::staticTopicName(bridge_->topicBase()).c_str());
}

void RunDds::printSummary() const {
  if (!bridge_) return;
  const dds::SegmentBridgeStats s = bridge_->stats();
  std::printf("  DDS (%s): %llu frames written, %llu skipped for a newer one, %llu write errors\n",
              dds::frameTopicName(bridge_->topicBase()).c_str(), static_cast<unsigned long long>(s.frames_written),
              static_cast<unsigned long long>(s.frames_skipped), static_cast<unsigned long long>(s.write_errors));
}

void RunDds::addStats(nlohmann::json& j) const {
  if (!bridge_) return;
  const dds::SegmentBridgeStats s = bridge_->stats();
  j["dds"] = {{"frame_topic", dds::frameTopicName(bridge_->topicBase())},
              {"static_topic", dds::staticTopicName(bridge_->topicBase())},
              {"frames_written", s.frames_written},
              {"frames_skipped", s.frames_skipped},
              {"write_errors", s.write_errors},
              {"read_busy", s.read_busy}};
}

#else

RunDds::RunDds(const RunOptions& options, const ShmPublisher&) {
  if (options.dds)
    throw std::runtime_error("--dds: this build has no DDS (install cyclonedds-dev and cyclonedds-tools, configure with -DTETRIG_DDS=ON)");
}
RunDds::~RunDds() = default;
void RunDds::stop() {}
void RunDds::printBanner() const {}
void RunDds::printSummary() const {}
void RunDds::addStats(nlohmann::json&) const {}

#endif

}  // namespace tetrig::tools
