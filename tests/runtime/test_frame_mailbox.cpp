// Tests for the latest-frame mailbox (runtime/src/frame_mailbox.cpp): hand-off semantics, drop
// accounting, slot ownership, no allocation, and a multi-thread stress run that checks that no
// consumer ever sees a torn frame. Also built with -fsanitize=thread (test_frame_mailbox_tsan).
#include "tetrig/frame_mailbox.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <new>
#include <thread>
#include <vector>

#include "counting_allocator.hpp"

namespace {

using tetrig::FrameMailbox;
using tetrig::MarkerFrame;

#ifndef TETRIG_MAILBOX_STRESS_FRAMES
#define TETRIG_MAILBOX_STRESS_FRAMES 40000
#endif

// Fills every field a torn copy could mix up with values derived from `counter`.
void stamp(MarkerFrame& f, std::uint64_t counter) {
  f.frame_counter = counter;
  f.device_timestamp_ns = static_cast<std::int64_t>(counter * 3u);
  f.receive_timestamp_ns = static_cast<std::int64_t>(counter * 5u);
  f.flags = static_cast<std::uint32_t>(counter);
  f.marker_count = static_cast<std::uint16_t>(tetrig::kMaxMarkers);
  f.rejected_count = static_cast<std::uint16_t>(counter & 0xFFFFu);
  const float c = static_cast<float>(counter & 0xFFFFFu);  // exact in float
  for (auto& m : f.markers) {
    m.position_mm[0] = c;
    m.position_mm[1] = -c;
    m.position_mm[2] = c + 0.5f;
    m.id = static_cast<std::uint16_t>(counter & 0xFFFFu);
    m.valid = 1;
    m.orientation[0] = c;
  }
}

// True when every field of `f` agrees with its frame_counter.
bool consistent(const MarkerFrame& f) {
  const std::uint64_t counter = f.frame_counter;
  if (f.device_timestamp_ns != static_cast<std::int64_t>(counter * 3u) ||
      f.receive_timestamp_ns != static_cast<std::int64_t>(counter * 5u) ||
      f.flags != static_cast<std::uint32_t>(counter) ||
      f.rejected_count != static_cast<std::uint16_t>(counter & 0xFFFFu) ||
      f.marker_count != tetrig::kMaxMarkers) {
    return false;
  }
  const float c = static_cast<float>(counter & 0xFFFFFu);
  for (const auto& m : f.markers) {
    if (m.position_mm[0] != c || m.position_mm[1] != -c || m.position_mm[2] != c + 0.5f ||
        m.id != static_cast<std::uint16_t>(counter & 0xFFFFu) || m.orientation[0] != c) {
      return false;
    }
  }
  return true;
}

TEST(FrameMailbox, EmptyMailboxYieldsNothingAndLeavesOutputAlone) {
  auto box = std::make_unique<FrameMailbox>();
  auto out = std::make_unique<MarkerFrame>();
  stamp(*out, 77);
  EXPECT_FALSE(box->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 77u);
  EXPECT_TRUE(consistent(*out));
  EXPECT_EQ(box->tryAcquireLatest(), nullptr);
  EXPECT_FALSE(box->hasPending());
  const auto s = box->stats();
  EXPECT_EQ(s.published, 0u);
  EXPECT_EQ(s.taken, 0u);
  EXPECT_EQ(s.dropped, 0u);
}

TEST(FrameMailbox, OneFrameIsTakenOnce) {
  auto box = std::make_unique<FrameMailbox>();
  auto in = std::make_unique<MarkerFrame>();
  auto out = std::make_unique<MarkerFrame>();
  stamp(*in, 5);
  box->publish(*in);
  EXPECT_TRUE(box->hasPending());
  ASSERT_TRUE(box->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 5u);
  EXPECT_TRUE(consistent(*out));
  EXPECT_FALSE(box->hasPending());
  EXPECT_FALSE(box->tryTakeLatest(*out));
  EXPECT_EQ(box->published(), 1u);
  EXPECT_EQ(box->taken(), 1u);
  EXPECT_EQ(box->dropped(), 0u);
}

// Fan-out (several performers on one source): a frame committed into the head of a chain reaches
// every mailbox of it, whole; each consumer takes it on its own; a lockstep producer sees the
// chain pending until the last consumer took it.
TEST(FrameMailbox, AForwardedFrameReachesEveryMailboxOfTheChain) {
  auto a = std::make_unique<FrameMailbox>();
  auto b = std::make_unique<FrameMailbox>();
  auto c = std::make_unique<FrameMailbox>();
  a->forwardTo(b.get());
  b->forwardTo(c.get());
  auto in = std::make_unique<MarkerFrame>();
  auto out = std::make_unique<MarkerFrame>();
  stamp(*in, 7);
  a->publish(*in);
  EXPECT_TRUE(a->hasPending());
  EXPECT_TRUE(b->hasPending());
  EXPECT_TRUE(c->hasPending());
  ASSERT_TRUE(a->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 7u);
  EXPECT_TRUE(consistent(*out));
  EXPECT_TRUE(a->pendingAlongChain()) << "b and c still hold the frame";
  ASSERT_TRUE(c->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 7u);
  EXPECT_TRUE(consistent(*out)) << "the forwarded copy is the whole frame";
  EXPECT_TRUE(a->pendingAlongChain());
  EXPECT_FALSE(c->pendingAlongChain()) << "a chain looks downstream only";
  stamp(*in, 8);
  a->publish(*in);  // b has not taken 7: it is dropped there, and only there
  ASSERT_TRUE(b->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 8u);
  EXPECT_TRUE(consistent(*out));
  EXPECT_EQ(b->dropped(), 1u);
  EXPECT_EQ(a->dropped(), 0u);
  EXPECT_EQ(c->dropped(), 0u);
  ASSERT_TRUE(a->tryTakeLatest(*out));
  ASSERT_TRUE(c->tryTakeLatest(*out));
  EXPECT_FALSE(a->pendingAlongChain());
  EXPECT_EQ(a->published(), 2u);
  EXPECT_EQ(b->published(), 2u);
  EXPECT_EQ(c->published(), 2u);
}

TEST(FrameMailbox, NewestFrameWinsAndOverwrittenFramesAreCountedAsDropped) {
  auto box = std::make_unique<FrameMailbox>();
  auto in = std::make_unique<MarkerFrame>();
  auto out = std::make_unique<MarkerFrame>();
  for (std::uint64_t c = 1; c <= 3; ++c) {
    stamp(*in, c);
    box->publish(*in);
  }
  ASSERT_TRUE(box->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 3u);
  EXPECT_EQ(box->dropped(), 2u);
  // Interleave: publish 4, take 4, publish 5 and 6, take 6.
  stamp(*in, 4);
  box->publish(*in);
  ASSERT_TRUE(box->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 4u);
  stamp(*in, 5);
  box->publish(*in);
  stamp(*in, 6);
  box->publish(*in);
  EXPECT_TRUE(box->hasPending());
  const auto s = box->stats();
  EXPECT_EQ(s.published, 6u);
  EXPECT_EQ(s.taken, 2u);
  EXPECT_EQ(s.dropped, 3u);
  EXPECT_EQ(s.published, s.taken + s.dropped + 1u);  // one pending
  ASSERT_TRUE(box->tryTakeLatest(*out));
  EXPECT_EQ(out->frame_counter, 6u);
  EXPECT_EQ(box->published(), box->taken() + box->dropped());
}

TEST(FrameMailbox, AcquiredFrameIsNotTouchedByLaterPublishes) {
  auto box = std::make_unique<FrameMailbox>();
  auto in = std::make_unique<MarkerFrame>();
  stamp(*in, 10);
  box->publish(*in);
  const MarkerFrame* held = box->tryAcquireLatest();
  ASSERT_NE(held, nullptr);
  // The producer cycles through every slot it may own many times; the consumer's slot is not one.
  for (std::uint64_t c = 11; c < 40; ++c) {
    MarkerFrame& slot = box->producerSlot();
    EXPECT_NE(&slot, held);
    stamp(slot, c);
    box->commit();
  }
  EXPECT_EQ(held->frame_counter, 10u);
  EXPECT_TRUE(consistent(*held));
  const MarkerFrame* next = box->tryAcquireLatest();
  ASSERT_NE(next, nullptr);
  EXPECT_EQ(next->frame_counter, 39u);
  EXPECT_TRUE(consistent(*next));
}

TEST(FrameMailbox, PublishAndTakeDoNotAllocate) {
  auto box = std::make_unique<FrameMailbox>();
  auto in = std::make_unique<MarkerFrame>();
  auto out = std::make_unique<MarkerFrame>();
  const std::uint64_t before = ::tetrig::test::allocationCount();
  for (std::uint64_t c = 1; c < 1000; ++c) {
    stamp(*in, c);
    box->publish(*in);
    if (c % 3 == 0) {
      EXPECT_TRUE(box->tryTakeLatest(*out));
    }
    (void)box->tryAcquireLatest();
  }
  EXPECT_EQ(::tetrig::test::allocationCount(), before);
}

// Several independent producer/consumer pairs (the mailbox is SPSC) plus observer threads that
// read the counters, all at once on a 2-core machine: every taken frame is whole, counters only
// grow, counter relations hold while running, and the books balance at the end.
TEST(FrameMailbox, StressNoTornFramesAndDropAccountingBalances) {
  constexpr int kPairs = 3;
  constexpr int kObservers = 2;
  constexpr std::uint64_t kFrames = TETRIG_MAILBOX_STRESS_FRAMES;

  std::vector<std::unique_ptr<FrameMailbox>> boxes;
  for (int i = 0; i < kPairs; ++i) {
    boxes.push_back(std::make_unique<FrameMailbox>());
  }
  std::atomic<int> torn{0};
  std::atomic<int> non_monotonic_frames{0};
  std::atomic<int> counter_violations{0};
  std::atomic<bool> consumers_done{false};
  std::vector<std::uint64_t> taken_seen(kPairs, 0);

  std::vector<std::thread> threads;
  for (int i = 0; i < kPairs; ++i) {
    FrameMailbox* box = boxes[static_cast<std::size_t>(i)].get();
    threads.emplace_back([box, i] {
      auto scratch = std::make_unique<MarkerFrame>();
      for (std::uint64_t c = 1; c <= kFrames; ++c) {
        // Alternate the copying and the zero-copy producer paths.
        if ((c + static_cast<std::uint64_t>(i)) % 2 == 0) {
          stamp(box->producerSlot(), c);
          box->commit();
        } else {
          stamp(*scratch, c);
          box->publish(*scratch);
        }
      }
    });
    threads.emplace_back([box, i, &torn, &non_monotonic_frames, &taken_seen] {
      auto out = std::make_unique<MarkerFrame>();
      std::uint64_t last = 0;
      std::uint64_t count = 0;
      while (last < kFrames) {
        bool got = false;
        if (count % 2 == 0) {
          got = box->tryTakeLatest(*out);
          if (got && !consistent(*out)) torn.fetch_add(1);
          if (got) {
            if (out->frame_counter <= last) non_monotonic_frames.fetch_add(1);
            last = out->frame_counter;
          }
        } else if (const MarkerFrame* f = box->tryAcquireLatest()) {
          got = true;
          if (!consistent(*f)) torn.fetch_add(1);
          if (f->frame_counter <= last) non_monotonic_frames.fetch_add(1);
          last = f->frame_counter;
        }
        if (got) {
          ++count;
        } else {
          std::this_thread::yield();
        }
      }
      taken_seen[static_cast<std::size_t>(i)] = count;
    });
  }
  for (int o = 0; o < kObservers; ++o) {
    threads.emplace_back([&boxes, &consumers_done, &counter_violations] {
      std::vector<tetrig::FrameMailboxStats> prev(boxes.size());
      while (!consumers_done.load()) {
        for (std::size_t b = 0; b < boxes.size(); ++b) {
          const auto s = boxes[b]->stats();
          if (s.published < prev[b].published || s.taken < prev[b].taken || s.dropped < prev[b].dropped ||
              s.taken + s.dropped > s.published) {
            counter_violations.fetch_add(1);
          }
          prev[b] = s;
        }
        std::this_thread::yield();
      }
    });
  }
  // Join producers and consumers (all but the observers), then stop the observers.
  for (std::size_t t = 0; t < static_cast<std::size_t>(2 * kPairs); ++t) {
    threads[t].join();
  }
  consumers_done.store(true);
  for (std::size_t t = static_cast<std::size_t>(2 * kPairs); t < threads.size(); ++t) {
    threads[t].join();
  }

  EXPECT_EQ(torn.load(), 0);
  EXPECT_EQ(non_monotonic_frames.load(), 0);
  EXPECT_EQ(counter_violations.load(), 0);
  for (int i = 0; i < kPairs; ++i) {
    const auto s = boxes[static_cast<std::size_t>(i)]->stats();
    EXPECT_EQ(s.published, kFrames);
    EXPECT_EQ(s.taken, taken_seen[static_cast<std::size_t>(i)]);
    EXPECT_FALSE(boxes[static_cast<std::size_t>(i)]->hasPending());  // the last frame was taken
    EXPECT_EQ(s.published, s.taken + s.dropped);
    EXPECT_GE(s.taken, 1u);
  }
}

// ---- waking the consumer (waitForFrame / wake) ----

TEST(FrameMailboxWait, ReturnsAtOnceWhenAFrameIsPendingAndFalseOnTimeout) {
  auto box = std::make_unique<FrameMailbox>();
  EXPECT_FALSE(box->waitForFrame(5'000'000));  // nothing published: times out
  EXPECT_FALSE(box->waitForFrame(0));
  MarkerFrame f;
  stamp(f, 1);
  box->publish(f);
  EXPECT_TRUE(box->waitForFrame(0));
  EXPECT_TRUE(box->waitForFrame(1'000'000'000));
  ASSERT_NE(box->tryAcquireLatest(), nullptr);
  EXPECT_FALSE(box->waitForFrame(1'000'000));  // taken: nothing pending again
}

TEST(FrameMailboxWait, APublishWakesASleepingConsumerAndWakeReleasesIt) {
  auto box = std::make_unique<FrameMailbox>();
  std::atomic<int> phase{0};
  bool first = false, second = true;
  std::chrono::steady_clock::duration first_wait{};
  std::thread consumer([&] {
    phase.store(1);
    const auto t0 = std::chrono::steady_clock::now();
    first = box->waitForFrame(60'000'000'000);  // 60 s: only the publish can end it early
    first_wait = std::chrono::steady_clock::now() - t0;
    (void)box->tryAcquireLatest();
    phase.store(2);
    second = box->waitForFrame(60'000'000'000);  // only wake() can end it early
  });
  while (phase.load() != 1) std::this_thread::yield();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // let it fall asleep
  MarkerFrame f;
  stamp(f, 7);
  box->publish(f);
  while (phase.load() != 2) std::this_thread::yield();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  box->wake();
  consumer.join();
  EXPECT_TRUE(first);
  EXPECT_LT(first_wait, std::chrono::seconds(30)) << "woken by the publish, not by the timeout";
  EXPECT_FALSE(second) << "wake() returns false: no frame pending";
}

// Many hand-offs with the consumer always asleep when it has nothing: a lost wake-up would leave
// it asleep for the full (long) timeout, which the test reports as a stall.
TEST(FrameMailboxWait, NoLostWakeUps) {
  auto box = std::make_unique<FrameMailbox>();
  constexpr std::uint64_t kFrames = TETRIG_MAILBOX_STRESS_FRAMES / 8;
  std::atomic<std::uint64_t> acknowledged{0};
  int stalls = 0;
  std::uint64_t last = 0;
  std::thread consumer([&] {
    while (last < kFrames) {
      const auto t0 = std::chrono::steady_clock::now();
      const bool got = box->waitForFrame(5'000'000'000);
      if (!got && std::chrono::steady_clock::now() - t0 >= std::chrono::seconds(4)) ++stalls;
      if (const MarkerFrame* f = box->tryAcquireLatest()) {
        last = f->frame_counter;
        acknowledged.store(last, std::memory_order_release);
      }
    }
  });
  MarkerFrame f;
  for (std::uint64_t k = 1; k <= kFrames; ++k) {
    stamp(f, k);
    box->publish(f);
    // Every 4th frame: wait until the consumer took it, so that it goes back to sleep before the next.
    if (k % 4 == 0) {
      while (acknowledged.load(std::memory_order_acquire) < k) std::this_thread::yield();
    }
  }
  consumer.join();
  EXPECT_EQ(stalls, 0);
  EXPECT_EQ(last, kFrames);
}

}  // namespace
