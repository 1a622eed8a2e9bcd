// Latest-frame mailbox: a lock-free single-producer / single-consumer triple buffer of MarkerFrames.
//
// Algorithm: the classic triple buffer. Three slots; the producer owns one ("back"), the consumer
// owns one ("front"), and the third ("middle") is held by one atomic word that also carries a
// "fresh" bit. publish() fills the back slot and swaps it into the middle with one atomic
// exchange; tryTakeLatest() swaps the middle with its front slot when the fresh bit is set. Each
// side only ever reads or writes the slot it owns, so no frame is ever torn and there is no data
// race (unlike a seqlock with plain copies). Neither side waits for the other.
//
// Guarantees:
//  - the consumer always gets the newest complete frame published before its call;
//  - a frame published but overwritten before the consumer took it is counted in dropped();
//  - at any quiescent point published() == taken() + dropped() + (hasPending() ? 1 : 0);
//  - nothing is allocated: the three slots live inside the object (about 3 x 9.3 KB, so create the
//    mailbox with new/make_unique or as a member, not on a small thread stack).
//
// Threads: exactly one producer thread (the driver's read loop) calls publish()/producerSlot()/
// commit(); exactly one consumer thread (the solver) calls tryTakeLatest()/tryAcquireLatest()/
// waitForFrame(). The counters and wake() may be used from any thread. Every member function
// except waitForFrame() is wait-free, and none allocates or throws.
//
// Waking the consumer (waitForFrame): an event count. commit() bumps a wake word and, only when
// the consumer has announced that it sleeps, wakes it with one futex call (Linux; elsewhere the
// consumer polls in 1 ms slices). The consumer reads the wake word, announces itself, re-checks
// for a fresh frame and sleeps only if the word is still the value it read, so a frame committed
// between its check and its sleep is never missed (all four accesses are sequentially consistent).
//
// Fan-out (several performers read from one source): forwardTo() chains mailboxes. Every frame
// committed here is also copied into the next mailbox and committed there, by the same producer
// thread, before this mailbox's own consumer sees it; so one source feeds several solver threads,
// each through its own triple buffer, with no extra thread and no extra wake-up on the way.
#pragma once

#include <atomic>
#include <cstdint>

#include "tetrig/marker_frame.hpp"

namespace tetrig {

// Snapshot of the mailbox counters (each read atomically; not one consistent snapshot while
// both sides are running).
struct FrameMailboxStats {
  std::uint64_t published = 0;  // frames committed by the producer
  std::uint64_t taken = 0;      // frames handed to the consumer
  std::uint64_t dropped = 0;    // frames overwritten by a newer one before the consumer took them
};

class FrameMailbox {
 public:
  FrameMailbox() noexcept;
  FrameMailbox(const FrameMailbox&) = delete;
  FrameMailbox& operator=(const FrameMailbox&) = delete;

  // ---- producer thread only ----

  // Copies `frame` into the producer's slot and publishes it (the newest frame replaces an
  // unread older one, which is then counted as dropped). Wait-free; copies sizeof(MarkerFrame).
  void publish(const MarkerFrame& frame) noexcept;

  // Zero-copy variant: the slot the producer owns. Decode directly into it, then commit().
  // The reference stays valid and private to the producer until commit(); its previous contents
  // are an older frame (not cleared), so overwrite every field you rely on.
  [[nodiscard]] MarkerFrame& producerSlot() noexcept { return slots_[back_]; }
  // Publishes the producer slot (see publish()), and forwards it along the fan-out chain.
  void commit() noexcept;

  // Control thread, before the producer starts: every frame committed here is then also
  // published to `next` (which may itself forward). `next` must outlive this mailbox's producer
  // and must have no other producer. nullptr ends the chain here.
  void forwardTo(FrameMailbox* next) noexcept { next_ = next; }
  // True when this mailbox or any mailbox it forwards to holds a frame not yet taken (a lockstep
  // producer waits for this to clear, so that no consumer of the chain drops a frame).
  [[nodiscard]] bool pendingAlongChain() const noexcept;

  // ---- consumer thread only ----

  // If a frame was published since the last take, copies the newest one into `out` and returns
  // true; otherwise returns false and leaves `out` unchanged. Wait-free.
  [[nodiscard]] bool tryTakeLatest(MarkerFrame& out) noexcept;

  // Zero-copy variant: returns the newest unread frame, or nullptr when there is none. The frame
  // is owned by the mailbox and stays valid and unchanged until the consumer's next call of
  // tryAcquireLatest() or tryTakeLatest().
  [[nodiscard]] const MarkerFrame* tryAcquireLatest() noexcept;

  // Sleeps until a frame is pending, wake() is called, or `timeout_ns` passes (no busy wait).
  // Returns hasPending() on return: false means timeout or wake(). Never allocates or throws.
  bool waitForFrame(std::int64_t timeout_ns) noexcept;

  // ---- any thread ----

  // True when a published frame waits to be taken (a hint while the producer is running).
  [[nodiscard]] bool hasPending() const noexcept;
  [[nodiscard]] std::uint64_t published() const noexcept { return published_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t taken() const noexcept { return taken_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }
  [[nodiscard]] FrameMailboxStats stats() const noexcept;
  // Wakes a consumer sleeping in waitForFrame() (e.g. to make it see a stop request).
  void wake() noexcept;

 private:
  static constexpr std::uint32_t kIndexMask = 0x3u;
  static constexpr std::uint32_t kFreshBit = 0x4u;
  static constexpr std::size_t kCacheLine = 64;

  MarkerFrame slots_[3];
  // Middle slot index | kFreshBit when it holds a frame the consumer has not taken.
  alignas(kCacheLine) std::atomic<std::uint32_t> middle_;
  // Producer-owned.
  alignas(kCacheLine) std::uint32_t back_;
  FrameMailbox* next_ = nullptr;  // fan-out chain (forwardTo); set before the producer starts
  std::atomic<std::uint64_t> published_{0};
  std::atomic<std::uint64_t> dropped_{0};
  // Consumer-owned.
  alignas(kCacheLine) std::uint32_t front_;
  std::atomic<std::uint64_t> taken_{0};
  // Event count for waitForFrame(): bumped by commit() and wake(); sleeping_ is set by the consumer.
  alignas(kCacheLine) std::atomic<std::uint32_t> wake_word_{0};
  std::atomic<std::uint32_t> sleeping_{0};
};

}  // namespace tetrig
