// Marker source factory: parses a source spec ("c3d:PATH", "replay:PATH", "synthetic[:N]", "synthetic:character",
// "hid:VID:PID", "usb:VID:PID", "hydra[:SERIAL]"; docs/drivers.md, "One source shape") and builds
// the matching MarkerSource.
#include "tetrig/drivers/source_factory.hpp"

#include <charconv>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <system_error>
#include <utility>

#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/device_marker_sources.hpp"
#include "tetrig/drivers/playback_sources.hpp"

namespace tetrig::devices {

namespace {

constexpr std::string_view kSpecForms =
    "c3d:PATH, replay:PATH, synthetic[:N], synthetic:character, hid:VID:PID, usb:VID:PID, hydra[:SERIAL] (VID, PID in hex, e.g. hid:1209:0001)";

[[noreturn]] void badSpec(std::string_view spec, const std::string& what) {
  throw std::invalid_argument("bad marker source \"" + std::string(spec) + "\": " + what + "; accepted: " +
                              std::string(kSpecForms));
}

std::uint16_t parseHex16(std::string_view spec, std::string_view text, const char* what) {
  unsigned value = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value, 16);
  if (text.empty() || text.size() > 4 || ec != std::errc() || ptr != end) {
    badSpec(spec, std::string(what) + " \"" + std::string(text) + "\" is not a hex number of 1-4 digits");
  }
  return static_cast<std::uint16_t>(value);
}

struct VidPid {
  std::uint16_t vendor_id;
  std::uint16_t product_id;
};

VidPid parseVidPid(std::string_view spec, std::string_view kind, std::string_view rest) {
  const std::size_t colon = rest.find(':');
  if (rest.empty() || colon == std::string_view::npos) {
    badSpec(spec, std::string(kind) + " needs a vendor and product id (" + std::string(kind) + ":VID:PID)");
  }
  return {parseHex16(spec, rest.substr(0, colon), "VID"), parseHex16(spec, rest.substr(colon + 1), "PID")};
}

std::filesystem::path existingFile(std::string_view spec, std::string_view kind, std::string_view rest) {
  if (rest.empty()) badSpec(spec, std::string(kind) + " needs a path (" + std::string(kind) + ":PATH)");
  std::filesystem::path path{std::string(rest)};
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw std::runtime_error(std::string(kind) + " source: " +
                             (std::filesystem::exists(path, ec) ? "not a regular file: " : "file not found: ") +
                             path.string());
  }
  return path;
}

void checkSpeed(std::string_view spec, double speed) {
  if (!(speed > 0.0) || !std::isfinite(speed)) {
    throw std::invalid_argument("marker source \"" + std::string(spec) + "\": speed must be a positive number");
  }
}

std::unique_ptr<drivers::MarkerSource> openC3D(std::string_view spec, std::string_view rest,
                                               const SourceOpenOptions& options) {
  const std::filesystem::path path = existingFile(spec, "c3d", rest);
  checkSpeed(spec, options.speed);
  drivers::C3DReadOptions read;
  read.keep_zero_points = options.c3d_keep_zero_points;
  auto clip = std::make_shared<const drivers::C3DClip>(drivers::C3DClip::load(path, read));
  drivers::C3DPlaybackOptions playback;
  playback.pacing = options.pacing;
  playback.speed = options.speed;
  playback.loop = options.loop;
  playback.max_frames = options.max_frames;
  playback.rate_override_hz = options.rate_hz;
  return drivers::makeC3DSource(std::move(clip), std::move(playback), path.string());
}

std::unique_ptr<drivers::MarkerSource> openReplay(std::string_view spec, std::string_view rest,
                                                  const SourceOpenOptions& options) {
  const std::filesystem::path path = existingFile(spec, "replay", rest);
  checkSpeed(spec, options.speed);
  if (options.loop || options.max_frames != 0) {
    throw std::invalid_argument("marker source \"" + std::string(spec) +
                                "\": a replay plays its recording once (loop and max_frames are for c3d and synthetic)");
  }
  return drivers::makeReplaySource(path, options.pacing, options.speed);
}

std::unique_ptr<drivers::MarkerSource> openSynthetic(std::string_view spec, std::string_view rest, bool has_rest,
                                                     const SourceOpenOptions& options) {
  checkSpeed(spec, options.speed);
  if (has_rest && rest == "character") {
    // The default character's own 41 markers and labels: synthetic_rest_mm and synthetic_labels
    // (a rig's) are not used; the rig binds the labels it shares with the character.
    drivers::SyntheticOptions character = drivers::characterSyntheticOptions();
    character.pacing = options.pacing;
    character.speed = options.speed;
    character.max_frames = options.max_frames;
    if (options.rate_hz > 0) character.rate_hz = options.rate_hz;
    return drivers::makeSyntheticSource(std::move(character), drivers::SyntheticSource::characterMarkerLabels());
  }
  drivers::SyntheticOptions synthetic;
  synthetic.rest_positions_mm = options.synthetic_rest_mm;
  if (!synthetic.rest_positions_mm.empty()) {
    synthetic.marker_count = static_cast<int>(synthetic.rest_positions_mm.size());
  } else if (!options.synthetic_labels.empty()) {
    synthetic.marker_count = static_cast<int>(options.synthetic_labels.size());  // checked against kMaxMarkers below
  }
  if (has_rest) {
    int n = 0;
    const char* end = rest.data() + rest.size();
    const auto [ptr, ec] = std::from_chars(rest.data(), end, n);
    if (rest.empty() || ec != std::errc() || ptr != end || n < 1 || n > kMaxMarkers) {
      badSpec(spec, "the marker count \"" + std::string(rest) + "\" is not a whole number in 1.." +
                        std::to_string(kMaxMarkers) + " (nor \"character\")");
    }
    if (!synthetic.rest_positions_mm.empty() && static_cast<std::size_t>(n) != synthetic.rest_positions_mm.size()) {
      throw std::invalid_argument("marker source \"" + std::string(spec) + "\": " + std::to_string(n) +
                                  " markers asked for but " + std::to_string(synthetic.rest_positions_mm.size()) +
                                  " rest positions given");
    }
    synthetic.marker_count = n;
  }
  synthetic.pacing = options.pacing;
  synthetic.speed = options.speed;
  synthetic.max_frames = options.max_frames;
  if (options.rate_hz > 0) synthetic.rate_hz = options.rate_hz;
  return drivers::makeSyntheticSource(std::move(synthetic), options.synthetic_labels);
}

// A marker-stream device (hid:VID:PID, usb:VID:PID): the ids into its transport's options, the rate
// it is asked for. The two kinds differ only in the transport member.
template <class Config, class Transport>
Config markerStreamConfig(std::string_view spec, std::string_view kind, std::string_view rest, const SourceOpenOptions& options,
                          Transport Config::*transport) {
  const VidPid id = parseVidPid(spec, kind, rest);
  Config config;
  (config.*transport).vendor_id = id.vendor_id;
  (config.*transport).product_id = id.product_id;
  config.rate_hz = options.rate_hz;
  return config;
}

}  // namespace

std::string_view markerSourceSpecForms() noexcept { return kSpecForms; }

std::unique_ptr<drivers::MarkerSource> openMarkerSource(std::string_view spec, const SourceOpenOptions& options) {
  const std::size_t colon = spec.find(':');
  const std::string_view kind = spec.substr(0, colon);
  const bool has_rest = colon != std::string_view::npos;
  const std::string_view rest = has_rest ? spec.substr(colon + 1) : std::string_view{};
  if (kind == "c3d") return openC3D(spec, rest, options);
  if (kind == "replay") return openReplay(spec, rest, options);
  if (kind == "synthetic") return openSynthetic(spec, rest, has_rest, options);
  if (kind == "hid")
    return makeHidMarkerStreamSource(markerStreamConfig(spec, kind, rest, options, &HidMarkerStreamSourceConfig::hid));
  if (kind == "usb")
    return makeUsbMarkerStreamSource(markerStreamConfig(spec, kind, rest, options, &UsbMarkerStreamSourceConfig::usb));
  if (kind == "hydra") {
    if (has_rest && rest.empty()) badSpec(spec, "hydra:SERIAL needs a serial after the colon");
    HydraSourceConfig config;
    config.hid.serial = std::string(rest);
    return makeHydraSource(std::move(config));
  }
  if (spec.empty()) badSpec(spec, "the spec is empty");
  badSpec(spec, "unknown kind \"" + std::string(kind) + "\"");
}

}  // namespace tetrig::devices
