// An outside C++20 program on the installed device sources (tetrig::devices, with libusb and hidapi):
// opens a synthetic source through the factory that also opens HID and USB devices, and lists its labels.
#include <tetrig/drivers/source_factory.hpp>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

int main() {
  tetrig::devices::SourceOpenOptions options;
  options.pacing = tetrig::drivers::Pacing::kAsFastAsPossible;
  const auto source = tetrig::devices::openMarkerSource("synthetic:3", options);
  std::vector<std::string> labels;
  if (!source->waitForLabels(std::chrono::milliseconds(0), labels) || labels.size() != 3) {
    std::fprintf(stderr, "consumer_devices: expected 3 labels\n");
    return 1;
  }
  std::printf("consumer_devices: %s %s %s (sources: %s)\n", labels[0].c_str(), labels[1].c_str(), labels[2].c_str(),
              std::string(tetrig::devices::markerSourceSpecForms()).c_str());
  return 0;
}
