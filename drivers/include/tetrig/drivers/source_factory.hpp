// One entry point for every marker source: a spec string ("c3d:walk.c3d", "hydra", ...) and a
// few options give a MarkerSource (marker_source.hpp) that the frame loop starts and stops
// without knowing its kind. In tetrig::devices because the device kinds link hidapi and libusb.
//
// Specs (docs/drivers.md, "One source shape"):
//   c3d:PATH         C3D playback (drivers::makeC3DSource): physical markers of the clip, mm,
//                    the file's axes; labels as stored ("meinard:LFHD"), "point<i>" when absent
//   replay:PATH      raw recording of a marker-stream device or a Razer Hydra, decoded and paced
//                    by its recorded receive times (drivers::makeReplaySource)
//   synthetic        synthetic markers (drivers::makeSyntheticSource); synthetic:N for N markers
//                    (1..256; default: as many as synthetic_rest_mm, else as many as
//                    synthetic_labels, else 41)
//   synthetic:character  the default character's performance (drivers::characterSyntheticOptions():
//                    its 41 HDM05-named markers at 120 Hz, 0.5 mm noise, dropouts, looped);
//                    synthetic_rest_mm and synthetic_labels are not used
//   hid:VID:PID      tetrig marker stream over HID (VID and PID hex, 1-4 digits: hid:1209:0001)
//   usb:VID:PID      tetrig marker stream over USB bulk
//   hydra            Razer Hydra (1532:0300); hydra:SERIAL opens only the device with that serial
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "tetrig/drivers/marker_source.hpp"
#include "tetrig/drivers/pacing.hpp"

namespace tetrig::devices {

// What each option applies to; an option a kind does not use is ignored, except that a replay
// refuses loop and max_frames (a recording plays once: a marker stream's frame counters would
// run backwards on a second pass).
struct SourceOpenOptions {
  drivers::Pacing pacing = drivers::Pacing::kRealTime;  // c3d, replay, synthetic
  double speed = 1.0;                                   // c3d, replay, synthetic (real time only)
  bool loop = false;                                    // c3d
  std::uint64_t max_frames = 0;                         // c3d, synthetic (0: no limit)
  std::uint16_t rate_hz = 0;  // > 0: devices (hid, usb) ask for this rate with SET_RATE; c3d plays
                              // at this rate instead of the clip's; synthetic produces at it
  bool c3d_keep_zero_points = false;  // c3d: C3DReadOptions::keep_zero_points (samples at x = y = z = 0
                                      // with residual 0 stay valid instead of being gaps)
  std::vector<std::array<float, 3>> synthetic_rest_mm;  // synthetic: rest positions in mm (e.g. a rig's markers)
  std::vector<std::string> synthetic_labels;            // synthetic: one label per marker (default M0..)
};

// Parses `spec` and builds the source (nothing is started and no device is opened: call start()).
// Throws std::invalid_argument with one line saying what is wrong and listing the accepted forms
// for a bad spec, and for options the kind cannot honour (synthetic:N against synthetic_rest_mm
// of another size, labels of the wrong count, speed <= 0, ...); std::runtime_error (C3DError,
// RawRecordingError) naming the path when a file is missing, unreadable or damaged.
// Allocates (a C3D clip or a recording is loaded whole); control thread.
std::unique_ptr<drivers::MarkerSource> openMarkerSource(std::string_view spec, const SourceOpenOptions& options);

// The accepted forms, one line, for usage messages:
// "c3d:PATH, replay:PATH, synthetic[:N], synthetic:character, hid:VID:PID, usb:VID:PID, hydra[:SERIAL] (VID, PID in hex)".
// Any thread; static string.
[[nodiscard]] std::string_view markerSourceSpecForms() noexcept;

}  // namespace tetrig::devices
