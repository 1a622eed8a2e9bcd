// std::vector with cache-line (64-byte) aligned storage, for the per-vertex vectors of the frame
// path: with kVectorStride = 4 doubles per vertex, a vertex's (x, y, z, pad) then never straddles
// two cache lines (with malloc's 16-byte alignment every other vertex did, and the loads and
// stores that split a line cost the solve and the rotation pass about 10 %, measured).
// Allocates only where std::vector would (load time on the frame path's buffers).
#pragma once

#include <cstddef>
#include <new>
#include <vector>

namespace tetrig {

template <class T, std::size_t Alignment = 64>
struct AlignedAllocator {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = AlignedAllocator<U, Alignment>;
  };
  AlignedAllocator() = default;
  template <class U>
  AlignedAllocator(const AlignedAllocator<U, Alignment>&) noexcept {}
  T* allocate(std::size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t{Alignment})); }
  void deallocate(T* p, std::size_t) noexcept { ::operator delete(p, std::align_val_t{Alignment}); }
  friend bool operator==(const AlignedAllocator&, const AlignedAllocator&) { return true; }
};

template <class T>
using AlignedVector = std::vector<T, AlignedAllocator<T>>;

}  // namespace tetrig
