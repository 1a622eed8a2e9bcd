// Counting global allocator for "this does not allocate" tests (STYLE: the test kit holds it).
// Link the object library `tetrig_counting_allocator` into a test binary: it replaces the global
// operator new/delete with malloc/free versions that count every allocation. Under ASan, run
// the binary with ASAN_OPTIONS=alloc_dealloc_mismatch=0 (blocks from ASan's own operator new
// made before main may reach the replacement delete).
#pragma once

#include <cstdint>

namespace tetrig::test {

// Allocations (operator new, all forms) made by this process so far, from any thread.
std::uint64_t allocationCount();

}  // namespace tetrig::test
