// Tests of the synthetic marker source: determinism for a seed, random access, the scripted
// motion (rest pose, rotation, rigidity, sway), dropout and noise statistics, pacing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "fake_clock.hpp"
#include "tetrig/drivers/synthetic_source.hpp"

namespace tetrig::drivers {
namespace {

bool sameMarkers(const MarkerFrame& a, const MarkerFrame& b) {
  if (a.marker_count != b.marker_count || a.frame_counter != b.frame_counter) return false;
  for (int i = 0; i < a.marker_count; ++i) {
    const Marker& x = a.markers[static_cast<std::size_t>(i)];
    const Marker& y = b.markers[static_cast<std::size_t>(i)];
    if (x.valid != y.valid || x.id != y.id || std::memcmp(x.position_mm, y.position_mm, sizeof(x.position_mm)) != 0) {
      return false;
    }
  }
  return true;
}

SyntheticOptions noisy(std::uint64_t seed) {
  SyntheticOptions o;
  o.marker_count = 30;
  o.noise_sigma_mm = 2.0f;
  o.dropout_probability = 0.02f;
  o.rotation_rate_deg_s = 45.0f;
  o.seed = seed;
  o.pacing = Pacing::kAsFastAsPossible;
  return o;
}

double dist(const float* a, const float* b) {
  const double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

TEST(SyntheticSource, DeterministicForASeedAndRandomAccess) {
  const SyntheticSource a(noisy(42));
  const SyntheticSource b(noisy(42));
  const SyntheticSource c(noisy(43));
  MarkerFrame fa, fb, fc;
  int differs = 0;
  for (std::uint64_t k = 0; k < 300; ++k) {
    a.fillFrame(k, fa);
    b.fillFrame(k, fb);
    c.fillFrame(k, fc);
    ASSERT_TRUE(sameMarkers(fa, fb)) << "frame " << k;
    differs += sameMarkers(fa, fc) ? 0 : 1;
  }
  EXPECT_GT(differs, 290);  // another seed gives other noise
  // Out of order == in order.
  MarkerFrame again;
  a.fillFrame(123, fa);
  a.fillFrame(7, again);
  a.fillFrame(123, again);
  EXPECT_TRUE(sameMarkers(fa, again));
  // run() produces exactly fillFrame's frames.
  SyntheticOptions o = noisy(42);
  o.max_frames = 50;
  SyntheticSource runner(o);
  std::uint64_t n = 0;
  bool ok = true;
  runner.run([&](const MarkerFrame& f) {
    a.fillFrame(n, fa);
    ok = ok && sameMarkers(f, fa);
    ++n;
  });
  EXPECT_TRUE(ok);
  EXPECT_EQ(n, 50u);
}

TEST(SyntheticSource, StillOptionsReproduceTheRestPose) {
  SyntheticOptions o;
  o.rest_positions_mm = {{10.0f, 20.0f, 30.0f}, {-5.0f, 0.0f, 1000.0f}, {0.0f, 0.0f, 0.0f}};
  o.sway_amplitude_mm = 0.0f;
  o.rotation_amplitude_deg = 0.0f;
  const SyntheticSource s(o);
  MarkerFrame f;
  s.fillFrame(77, f);
  ASSERT_EQ(f.marker_count, 3);
  EXPECT_EQ(f.frame_counter, 77u);
  EXPECT_EQ(f.device_timestamp_ns, 77 * s.framePeriodNs());
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(f.markers[i].valid, 1);
    EXPECT_EQ(f.markers[i].id, i);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(f.markers[i].position_mm[c], o.rest_positions_mm[i][static_cast<std::size_t>(c)], 1e-3);
  }
}

TEST(SyntheticSource, ConstantRotationAboutTheAxis) {
  SyntheticOptions o;
  o.rest_positions_mm = {{100.0f, 0.0f, 900.0f}, {0.0f, 50.0f, 400.0f}};
  o.rate_hz = 1.0;
  o.sway_amplitude_mm = 0.0f;
  o.rotation_amplitude_deg = 0.0f;
  o.rotation_rate_deg_s = 90.0f;  // right-handed about +z through (0, 0, 900)
  const SyntheticSource s(o);
  MarkerFrame f;
  s.fillFrame(1, f);  // t = 1 s: 90 degrees
  EXPECT_NEAR(f.markers[0].position_mm[0], 0.0f, 1e-3);
  EXPECT_NEAR(f.markers[0].position_mm[1], 100.0f, 1e-3);
  EXPECT_NEAR(f.markers[0].position_mm[2], 900.0f, 1e-3);
  EXPECT_NEAR(f.markers[1].position_mm[0], -50.0f, 1e-3);
  EXPECT_NEAR(f.markers[1].position_mm[1], 0.0f, 1e-3);
  EXPECT_NEAR(f.markers[1].position_mm[2], 400.0f, 1e-3);
}

TEST(SyntheticSource, RotationIsRigidAndSwayIsBounded) {
  SyntheticOptions o;
  o.marker_count = 20;
  o.rotation_axis = {1.0f, 2.0f, 3.0f};
  o.rotation_rate_deg_s = 33.0f;
  o.sway_amplitude_mm = 0.0f;
  const SyntheticSource rigid(o);
  const auto rest = SyntheticSource::defaultRestPositions(20);
  MarkerFrame f;
  for (std::uint64_t k : {1u, 50u, 333u}) {
    rigid.fillFrame(k, f);
    for (std::size_t i = 0; i < 20; ++i) {
      for (std::size_t j = i + 1; j < 20; ++j) {
        EXPECT_NEAR(dist(f.markers[i].position_mm, f.markers[j].position_mm), dist(rest[i].data(), rest[j].data()), 1e-2);
      }
    }
  }
  // Sway only: every marker stays within the amplitude of its rest position, along one axis.
  o.rotation_rate_deg_s = 0.0f;
  o.rotation_amplitude_deg = 0.0f;
  o.sway_amplitude_mm = 25.0f;
  const SyntheticSource sway(o);
  double largest = 0.0;
  for (std::uint64_t k = 0; k < 240; ++k) {
    sway.fillFrame(k, f);
    for (std::size_t i = 0; i < 20; ++i) {
      const double d = dist(f.markers[i].position_mm, rest[i].data());
      EXPECT_LE(d, 25.0 + 1e-3);
      largest = std::max(largest, d);
    }
  }
  EXPECT_GT(largest, 24.0);  // the full amplitude is reached over one period (2 s at 120 Hz)
}

TEST(SyntheticSource, DropoutAndNoiseStatistics) {
  SyntheticOptions o;
  o.marker_count = 50;
  o.sway_amplitude_mm = 0.0f;
  o.rotation_amplitude_deg = 0.0f;
  o.dropout_probability = 0.03f;
  o.dropout_max_frames = 5;
  o.noise_sigma_mm = 1.5f;
  o.seed = 9;
  const SyntheticSource s(o);
  SyntheticOptions clean = o;
  clean.dropout_probability = 0.0f;
  clean.noise_sigma_mm = 0.0f;
  const SyntheticSource ref(clean);
  MarkerFrame f, g;
  std::size_t invalid = 0, total = 0, runs = 0, longest = 0;
  std::vector<std::size_t> run_length(50, 0);
  double sum = 0.0, sum_sq = 0.0;
  std::size_t samples = 0;
  for (std::uint64_t k = 0; k < 2000; ++k) {
    s.fillFrame(k, f);
    ref.fillFrame(k, g);
    for (std::size_t i = 0; i < 50; ++i) {
      ++total;
      if (f.markers[i].valid == 0) {
        ++invalid;
        if (run_length[i]++ == 0) ++runs;
        longest = std::max(longest, run_length[i]);
        continue;
      }
      run_length[i] = 0;
      for (int c = 0; c < 3; ++c) {
        const double e = static_cast<double>(f.markers[i].position_mm[c]) - g.markers[i].position_mm[c];
        sum += e;
        sum_sq += e * e;
        ++samples;
      }
    }
  }
  // Gap starts at p = 0.03 with mean length 3: about 8-9 % of samples invalid (overlaps merge).
  const double fraction = static_cast<double>(invalid) / static_cast<double>(total);
  EXPECT_GT(fraction, 0.06);
  EXPECT_LT(fraction, 0.11);
  EXPECT_GT(runs, 1000u);
  EXPECT_GE(longest, 5u);
  const double mean = sum / static_cast<double>(samples);
  const double sigma = std::sqrt(sum_sq / static_cast<double>(samples) - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.05);
  EXPECT_NEAR(sigma, 1.5, 0.05);
}

TEST(SyntheticSource, PacingScheduleAndValidation) {
  using test::FakeClock;
  SyntheticOptions o;
  o.rate_hz = 200.0;
  o.max_frames = 4;
  SyntheticSource s(o);
  std::int64_t now = 100;
  std::vector<std::int64_t> sleeps;
  std::vector<std::int64_t> stamps;
  const PacedRunStats stats =
      s.run([&](const MarkerFrame& f) { stamps.push_back(f.receive_timestamp_ns); }, nullptr, FakeClock{&now, &sleeps});
  EXPECT_EQ(stats.items, 4u);
  EXPECT_EQ(stamps, (std::vector<std::int64_t>{100, 5'000'100, 10'000'100, 15'000'100}));

  SyntheticOptions bad;
  bad.marker_count = kMaxMarkers + 1;
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
  bad = {};
  bad.rate_hz = 0.0;
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
  bad = {};
  bad.rotation_axis = {0.0f, 0.0f, 0.0f};
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
  bad = {};
  bad.dropout_max_frames = 0;
  EXPECT_THROW(SyntheticSource{bad}, std::invalid_argument);
}

}  // namespace
}  // namespace tetrig::drivers
