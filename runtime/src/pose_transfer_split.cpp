// Two-core pose transfer (tetrig/pose_transfer_split.hpp).
//
// Protocol for one job (apply): the caller writes x_/out_, resets next_chunk_ to 0, bumps job_ and
// wakes the worker through wake_ (its futex word; the worker re-reads job_ after every wake-up). Both threads take chunk indices with next_chunk_.fetch_add until
// they run past the last chunk. The worker sets busy_ = 1 before it takes its first chunk of a job
// and clears it (release) after its last; the caller, once the counter is exhausted, spins until
// busy_ is 0, so every row is written before apply() returns. The worker re-checks job_ after
// setting busy_ (seq_cst on both sides), so a worker that wakes after the caller has already
// finished the job takes no chunk of it: next_chunk_ is exhausted, and the next job's reset
// happens only after the caller saw busy_ == 0.
#include "tetrig/pose_transfer_padded.hpp"
#include "tetrig/pose_transfer_split.hpp"

#include "futex.hpp"

#include <algorithm>

namespace tetrig {

PoseTransferSplit::PoseTransferSplit(const PoseTransferView<double>& b, std::int32_t chunk_rows)
    : b_(b), rows_(b.rows), chunk_rows_(std::max<std::int32_t>(1, chunk_rows)) {
  start();
}

PoseTransferSplit::PoseTransferSplit(const BlockedPoseTransferView& b, std::int32_t chunk_rows)
    : blocked_(b), rows_(b.blocks), chunk_rows_((std::max<std::int32_t>(1, chunk_rows) + kPoseBlockRows - 1) / kPoseBlockRows) {
  start();
}

void PoseTransferSplit::start() {
  chunks_ = (rows_ + chunk_rows_ - 1) / chunk_rows_;
  next_chunk_.store(static_cast<std::uint32_t>(chunks_), std::memory_order_relaxed);  // nothing to take yet
  worker_ = std::thread([this] { work(); });
}

PoseTransferSplit::~PoseTransferSplit() {
  stop_.store(true, std::memory_order_seq_cst);
  wake_.fetch_add(1, std::memory_order_seq_cst);
  detail::futexWakeAll(wake_);
  if (worker_.joinable()) worker_.join();
}

void PoseTransferSplit::runChunks(bool worker) noexcept {
  const auto chunks = static_cast<std::uint32_t>(chunks_);
  for (std::uint32_t c = next_chunk_.fetch_add(1, std::memory_order_acq_rel); c < chunks;
       c = next_chunk_.fetch_add(1, std::memory_order_acq_rel)) {
    const std::int32_t begin = static_cast<std::int32_t>(c) * chunk_rows_;
    const std::int32_t end = std::min(rows_, begin + chunk_rows_);
    const void* x = x_.load(std::memory_order_acquire);
    float* out = out_.load(std::memory_order_acquire);
    if (blocked_.rows > 0) {
      applyPoseTransferBlocked(blocked_, static_cast<const float*>(x), out, begin, end);
    } else {
      applyPoseTransferPaddedRows(b_, static_cast<const double*>(x), out, begin, end);
    }
    if (worker) worker_chunks_.fetch_add(1, std::memory_order_relaxed);
  }
}

void PoseTransferSplit::apply(const double* x_tet4, float* x_fine) noexcept {
  if (blocked_.rows == 0) run(x_tet4, x_fine);
}

void PoseTransferSplit::apply(const float* x_tet4, float* x_fine) noexcept {
  if (blocked_.rows > 0) run(x_tet4, x_fine);
}

void PoseTransferSplit::run(const void* x_tet4, float* x_fine) noexcept {
  x_.store(x_tet4, std::memory_order_release);
  out_.store(x_fine, std::memory_order_release);
  next_chunk_.store(0, std::memory_order_seq_cst);
  job_.fetch_add(1, std::memory_order_seq_cst);
  wake_.fetch_add(1, std::memory_order_seq_cst);
  detail::futexWakeAll(wake_);
  runChunks(false);
  while (busy_.load(std::memory_order_acquire) != 0u) {
  }
}

void PoseTransferSplit::work() noexcept {
  std::uint32_t seen_wake = wake_.load(std::memory_order_seq_cst);
  std::uint32_t seen_job = job_.load(std::memory_order_seq_cst);
  while (true) {
    detail::futexWait(wake_, seen_wake, 1'000'000'000);
    if (stop_.load(std::memory_order_seq_cst)) return;
    seen_wake = wake_.load(std::memory_order_seq_cst);
    const std::uint32_t job = job_.load(std::memory_order_seq_cst);
    if (job == seen_job) continue;
    seen_job = job;
    busy_.store(1u, std::memory_order_seq_cst);
    // Take chunks only of the job that is current once busy_ is set (see the protocol above).
    if (job_.load(std::memory_order_seq_cst) == job) runChunks(true);
    busy_.store(0u, std::memory_order_release);
  }
}

}  // namespace tetrig
