// Latest-frame mailbox: lock-free SPSC triple buffer (see frame_mailbox.hpp for the algorithm).
//
// Memory ordering: the producer writes its slot with plain stores, then exchanges the slot index
// into middle_ with release semantics; the consumer's exchange acquires it before reading the
// slot. The reverse direction (the consumer hands its old slot back through middle_ with release;
// the producer acquires it before overwriting) keeps the consumer's reads before the producer's
// later writes. Counters are incremented so that an observer that reads taken/dropped first and
// published last (stats()) always sees taken + dropped <= published.
#include "tetrig/frame_mailbox.hpp"

#include "futex.hpp"

#include <algorithm>

namespace tetrig {

using detail::futexWait;
using detail::futexWakeAll;

namespace {

// The frame's header and its markers[0 .. marker_count) (the rest of a slot is never read).
void copyFrame(const MarkerFrame& from, MarkerFrame& to) noexcept {
  to.frame_counter = from.frame_counter;
  to.device_timestamp_ns = from.device_timestamp_ns;
  to.receive_timestamp_ns = from.receive_timestamp_ns;
  to.flags = from.flags;
  to.marker_count = from.marker_count;
  to.rejected_count = from.rejected_count;
  const std::size_t n = std::min<std::size_t>(from.marker_count, from.markers.size());
  std::copy_n(from.markers.begin(), n, to.markers.begin());
}

}  // namespace

FrameMailbox::FrameMailbox() noexcept : middle_(1u), back_(0u), front_(2u) {}

void FrameMailbox::commit() noexcept {
  // The next mailbox of the chain gets its copy first (a plain copy into a slot only this
  // producer thread touches); it is handed over after this mailbox's own consumer got the frame.
  if (next_ != nullptr) copyFrame(slots_[back_], next_->producerSlot());
  // Count before the hand-off so that no observer can see a take or a drop of this frame first.
  published_.fetch_add(1, std::memory_order_acq_rel);
  const std::uint32_t previous = middle_.exchange(back_ | kFreshBit, std::memory_order_acq_rel);
  back_ = previous & kIndexMask;
  if ((previous & kFreshBit) != 0u) {
    dropped_.fetch_add(1, std::memory_order_acq_rel);
  }
  wake_word_.fetch_add(1, std::memory_order_seq_cst);
  if (sleeping_.load(std::memory_order_seq_cst) != 0u) futexWakeAll(wake_word_);
  if (next_ != nullptr) next_->commit();
}

bool FrameMailbox::pendingAlongChain() const noexcept {
  for (const FrameMailbox* m = this; m != nullptr; m = m->next_)
    if (m->hasPending()) return true;
  return false;
}

void FrameMailbox::wake() noexcept {
  wake_word_.fetch_add(1, std::memory_order_seq_cst);
  futexWakeAll(wake_word_);
}

bool FrameMailbox::waitForFrame(std::int64_t timeout_ns) noexcept {
  if ((middle_.load(std::memory_order_seq_cst) & kFreshBit) != 0u) return true;
  if (timeout_ns <= 0) return false;
  const std::uint32_t word = wake_word_.load(std::memory_order_seq_cst);
  sleeping_.store(1u, std::memory_order_seq_cst);
  if ((middle_.load(std::memory_order_seq_cst) & kFreshBit) == 0u) futexWait(wake_word_, word, timeout_ns);
  sleeping_.store(0u, std::memory_order_seq_cst);
  return (middle_.load(std::memory_order_acquire) & kFreshBit) != 0u;
}

void FrameMailbox::publish(const MarkerFrame& frame) noexcept {
  slots_[back_] = frame;
  commit();
}

const MarkerFrame* FrameMailbox::tryAcquireLatest() noexcept {
  if ((middle_.load(std::memory_order_relaxed) & kFreshBit) == 0u) {
    return nullptr;
  }
  // Only the consumer clears the fresh bit, so it is still set here: the exchange takes a frame.
  const std::uint32_t previous = middle_.exchange(front_, std::memory_order_acq_rel);
  front_ = previous & kIndexMask;
  taken_.fetch_add(1, std::memory_order_acq_rel);
  return &slots_[front_];
}

bool FrameMailbox::tryTakeLatest(MarkerFrame& out) noexcept {
  const MarkerFrame* frame = tryAcquireLatest();
  if (frame == nullptr) {
    return false;
  }
  out = *frame;
  return true;
}

bool FrameMailbox::hasPending() const noexcept {
  return (middle_.load(std::memory_order_acquire) & kFreshBit) != 0u;
}

FrameMailboxStats FrameMailbox::stats() const noexcept {
  FrameMailboxStats s;
  s.taken = taken_.load(std::memory_order_acquire);
  s.dropped = dropped_.load(std::memory_order_acquire);
  s.published = published_.load(std::memory_order_acquire);
  return s;
}

}  // namespace tetrig
