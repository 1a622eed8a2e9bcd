// The pose transfer x_fine = B x_tet (Stoll et al. 2007, eq. 2.12) on two cores: the calling
// thread (the solver) and one worker thread made at load share the rows of B in chunks. Both take
// the next chunk from one atomic counter until none is left, so a worker that wakes late costs at
// most one chunk of waiting, and a worker that does not wake at all leaves every chunk to the
// caller (never slower than one thread by more than a futex wake). Every row is computed exactly
// as applyPoseTransferPaddedRows computes it, so the result is bit for bit the single-thread one
// whatever the split.
//
// Measured (docs/live.md, "Threads"): 0.55-0.6x the single-thread time in a hot loop
// (BM_LiveRigFrame/smpl_hdm05/1), but no gain in the live path at 120 Hz on the 2-core machines
// (the worker wakes from sleep every frame and the product is memory-bound), and a worker woken
// early to spin for the job made the solver slower (it competes with the driver thread and the
// consumer for 2 cores). Opt-in: `tetrig run --pose-threads 2`.
//
// Threads: construct and destroy on a control thread (load time: starts and joins the worker;
// allocates, may throw std::system_error). apply() from one thread at a time (the solver): no
// allocation, no lock, no exception; it waits (spinning, at most one chunk) for the worker's chunk
// in flight. The worker sleeps on a futex between frames.
#pragma once

#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_padded.hpp"
#include "tetrig/pose_transfer_blocked.hpp"

#include <atomic>
#include <cstdint>
#include <thread>

namespace tetrig {

class PoseTransferSplit {
 public:
  // `b` (the rig's B, or its blocked copy) must outlive this object. chunk_rows: rows per chunk (>= 1;
  // for the blocked copy rounded up to whole blocks).
  explicit PoseTransferSplit(const PoseTransferView<double>& b, std::int32_t chunk_rows = 512);
  explicit PoseTransferSplit(const BlockedPoseTransferView& b, std::int32_t chunk_rows = 512);
  ~PoseTransferSplit();
  PoseTransferSplit(const PoseTransferSplit&) = delete;
  PoseTransferSplit& operator=(const PoseTransferSplit&) = delete;

  // x_fine (b.rows x 3 floats) = B x_tet4: b.cols x 4 doubles (e.g. Deformer::paddedPositions()) for
  // the rig's B, b.cols x 4 floats (Deformer::paddedFloatPositions(), the float kernel) for the
  // blocked copy. The other overload of each writes nothing (a precondition, checked).
  void apply(const double* x_tet4, float* x_fine) noexcept;
  void apply(const float* x_tet4, float* x_fine) noexcept;

  // Chunks the worker computed so far (any thread; for tests and stats).
  [[nodiscard]] std::uint64_t workerChunks() const noexcept { return worker_chunks_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::int32_t chunkCount() const noexcept { return chunks_; }

 private:
  void start();
  void work() noexcept;
  void runChunks(bool worker) noexcept;
  void run(const void* x_tet4, float* x_fine) noexcept;

  PoseTransferView<double> b_;                 // used when blocked_ is empty (rows 0)
  BlockedPoseTransferView blocked_;
  std::int32_t rows_ = 0;                      // rows of b_, or blocks of blocked_: what the chunks split
  std::int32_t chunk_rows_ = 0, chunks_ = 0;    // chunk_rows_: rows of b_, or blocks of blocked_, per chunk
  // The job's input and output, stored before next_chunk_ is reset (atomic: a late worker may read
  // them while the caller starts the next job; it then computes that job's rows, correctly).
  std::atomic<const void*> x_{nullptr};  // const double* for b_, const float* for blocked_
  std::atomic<float*> out_{nullptr};
  alignas(64) std::atomic<std::uint32_t> job_{0};        // bumped by apply()
  alignas(64) std::atomic<std::uint32_t> wake_{0};       // bumped to wake the worker; it sleeps on it
  alignas(64) std::atomic<std::uint32_t> next_chunk_{0};  // next chunk to take, this job
  alignas(64) std::atomic<std::uint32_t> busy_{0};        // 1 while the worker runs chunks of a job
  std::atomic<std::uint64_t> worker_chunks_{0};
  std::atomic<bool> stop_{false};
  std::thread worker_;
};

}  // namespace tetrig
