// The playback sources behind the one MarkerSource shape (marker_source.hpp): a C3D clip, the
// synthetic source and the replay of a raw device recording, each producing on its own driver
// thread into the FrameMailbox given to start().
//
// Common behaviour of the three (docs/drivers.md, "One source shape"):
//  - start(mailbox) starts one std::thread that runs the playback (C3DPlayback::run,
//    SyntheticSource::run, RawReplay::run) and makes that thread the mailbox's single producer;
//    each frame is written into mailbox.producerSlot(), stamped receive_timestamp_ns =
//    tetrig::monotonicNowNs() right before mailbox.commit(). start() on a running source returns
//    false; after stop() or the end of a playback, start() plays again from the beginning.
//  - Real-time pacing sleeps on CLOCK_MONOTONIC through a condition variable that stop() signals
//    (each wait is at most 10 ms long), so stop() returns promptly even in a long gap of a
//    recording or at a very slow speed; a frame whose sleep stop() cut short is not published,
//    and nothing is published after stop() returns.
//  - stop() sets the stop flag and joins; idempotent; the destructor calls it.
//  - finished() becomes true when the playback has published its last frame on its own (end of
//    the clip or recording without loop, or max_frames reached); not when stop() ended the run,
//    never for an endless (looping or unlimited synthetic) playback.
//  - waitForLabels() answers at once: the labels are known at construction.
//  - stats(): frames_published, rejected_markers (sum of the frames' rejected_count) and, for a
//    replay, decode_errors and frames_lost, updated per frame; late_frames is the pacing's count
//    of frames released more than one period (replay: one record gap + 1 ms) late, updated when
//    the run ends (the pacing loops keep it to themselves while running); connected = the driver
//    thread is running.
//
// The driver thread allocates nothing and throws nothing per frame (the C3D and synthetic frames
// are filled in the playback's own buffer and copied into the mailbox slot; a replay decodes
// straight into the slot). It takes one mutex only to sleep on the condition variable.
// Threads: as for every MarkerSource (marker_source.hpp): the make* functions, start(), stop()
// and waitForLabels() on one control thread; stats(), finished() from any thread.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/marker_source.hpp"
#include "tetrig/drivers/pacing.hpp"
#include "tetrig/drivers/synthetic_source.hpp"

namespace tetrig::drivers {

// C3D playback of `clip` (shared: the source keeps it alive) with the C3DPlayback options
// (selection, units, axes, pacing, speed, loop, max_frames, rate override). `name` is what
// describe() calls the clip ("walk.c3d" -> "c3d:walk.c3d, 41 markers, 120 Hz").
// Frames are C3DPlayback's: markers[k].id = the C3D point index of the k-th selected point,
// positions in mm (file axes unless options.axes says otherwise), frame_counter = output index.
// Labels: labels[p] for each selected point index p (the first kMaxMarkers selected) is the
// clip's label as stored, subject prefix kept ("meinard:LFHD"; the runtime's binding matches it
// to a rig marker "LFHD"); a point without a label (files without a POINT:LABELS parameter, or
// selected unlabelled points) is named "point<p>", the name `tetrig build-rig` gives it, so a rig
// built from such a clip binds to its playback. Ids that are not selected have "" (unnamed).
// nominalRateHz() = the clip's rate, or options.rate_override_hz when > 0, times options.speed with
// real-time pacing (the rate frames arrive at, which sets tetrig run's default budget).
// Throws std::invalid_argument for a null clip and whatever C3DPlayback's constructor throws
// (unknown label, speed <= 0, real-time pacing without a rate). Allocates; control thread.
std::unique_ptr<MarkerSource> makeC3DSource(std::shared_ptr<const C3DClip> clip, C3DPlaybackOptions options,
                                            std::string name);

// Synthetic source (synthetic_source.hpp) with options.pacing / speed / max_frames (0: endless,
// finished() never becomes true). Markers have ids 0..n-1; labels[i] = labels[i] as given, or
// "M0".."M<n-1>" when `labels` is empty. nominalRateHz() = options.rate_hz (times options.speed with
// real-time pacing).
// Throws std::invalid_argument for what SyntheticSource rejects and for a non-empty `labels`
// whose size is not the marker count. Allocates; control thread.
std::unique_ptr<MarkerSource> makeSyntheticSource(SyntheticOptions options, std::vector<std::string> labels = {});

// Replay of a raw recording (docs/recording.md) through the decoder of the device that made it,
// paced by the recorded receive times (RawReplay: real time / speed, or as fast as possible),
// played once. The recording is loaded at construction (a cut-short last record is dropped).
// Which decoder:
//  - the header's VID:PID is 1532:0300 (Razer Hydra), or the first non-empty record is 52 bytes:
//    HydraDecoder on every record; markers 0 and 1 are labelled "hydra0", "hydra1";
//  - otherwise a tetrig marker stream, chosen per record: a 64-byte record whose first byte is
//    the report id 0x01 is a HID input report (MarkerStreamDecoder::decodeHidReport), any other
//    record one whole message (frame or descriptor) as a USB bulk transfer carries it
//    (decodeFrame). The first non-empty record must look like one of the two (a 64-byte report
//    with id 0x01, or the magic "TMSF" / "TMSD"), else std::invalid_argument. Labels come from
//    the first descriptor message in the recording, found at construction by decoding records
//    until one is accepted: labels[id] = its label for every id it names ("" for the others). A
//    recording without a descriptor has no labels: waitForLabels() returns false at once.
//    Descriptors later in the recording are decoded (the decoder's table follows them) but do
//    not change the labels the source reported.
// Records the decoder rejects are counted in stats().decode_errors; frames_lost is the decoder's
// count of sequence gaps. nominalRateHz() = 1e9 / the median interval between the recorded
// receive times of the records that completed the first 64 frames (0 with fewer than 2 frames),
// times `speed` with real-time pacing.
// Throws RawRecordingError (a std::runtime_error naming the file) when the recording cannot be
// read, std::invalid_argument for speed <= 0, an empty recording or an unknown kind.
// Allocates (the whole recording is held in memory); control thread.
std::unique_ptr<MarkerSource> makeReplaySource(std::filesystem::path recording, Pacing pacing, double speed = 1.0);

}  // namespace tetrig::drivers
