/* tetrig_shm.h: reader of the tetrig shared-memory segment (runtime -> game engine), layout
 * version 1.1 (reads 1.0 segments too: they have no marker positions). The format is documented in docs/shm.md; the writer is tetrig::ShmPublisher
 * (runtime/include/tetrig/shm_publisher.hpp).
 *
 * Implements: a POSIX shared-memory segment with a fixed header, static data written once before
 * the segment becomes visible (magic stored last, release), and N >= 3 dynamic slots written
 * round-robin under a per-slot sequence word (a seqlock: Lamport's "concurrent reading and writing"
 * as analysed for the C/C++ memory model by Boehm, "Can seqlocks get along with programming
 * language memory models?", MSPC 2012). Every access to a slot word is a relaxed atomic word
 * access; the sequence word orders them with release/acquire fences, so a reader never returns a
 * torn frame and there is no data race for ThreadSanitizer to find.
 *
 * Use: one C99 header, libc only (shm_open, mmap, fstat, kill, clock_gettime), no C++ and no
 * library. Compiles as C99 (gcc -std=c99 -pedantic -Wall -Wextra -Werror) and as C++.
 * Needs GCC or Clang (the __atomic builtins) on a little-endian host.
 *
 * POSIX feature macro: in strict ISO C mode (-std=c99, which hides POSIX declarations in glibc)
 * this header defines _POSIX_C_SOURCE 200809L itself when no feature macro is set, which only
 * works when it is included BEFORE any system header. Otherwise compile with
 * -D_POSIX_C_SOURCE=200809L (or _GNU_SOURCE / _DEFAULT_SOURCE); the header stops with an #error
 * naming this when POSIX.1-2008 is not visible. In -std=gnu99 and in C++ nothing is needed.
 *
 * Threads: a TetrigShmReader is used by one thread at a time; any number of readers (threads or
 * processes), each with its own TetrigShmReader, may read one segment at once. Readers never
 * write to the segment (read-only mapping) and never block the writer.
 *
 * Trust: tetrig_shm_open() requires the segment to belong to the reader's effective uid
 * (tetrig_shm_open_as() names another owner) and refuses one that group or others may write. The
 * owner can still rewrite any byte at any time: the reader copies and checks the header once at
 * open and never re-reads a static field (see TetrigShmReader), so no rewrite makes it divide by
 * zero or read outside its mapping. Truncating the segment (ftruncate by its owner) makes
 * accesses past the new end fault with SIGBUS: that is why the owner must be one you trust.
 *
 * Allocation: none. tetrig_shm_open() makes system calls (shm_open, fstat, mmap);
 * tetrig_shm_read_latest() and the accessors make none; tetrig_shm_producer_status() calls
 * kill(pid, 0) and on Linux reads /proc/<pid>/stat; tetrig_shm_name_status() calls shm_open and
 * fstat. */
#ifndef TETRIG_SHM_H
#define TETRIG_SHM_H

#if !defined(__cplusplus) && defined(__STRICT_ANSI__) && !defined(_POSIX_C_SOURCE) && \
    !defined(_XOPEN_SOURCE) && !defined(_GNU_SOURCE) && !defined(_DEFAULT_SOURCE)
#define _POSIX_C_SOURCE 200809L
#endif

#include <errno.h>
#include <fcntl.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <time.h>
#include <unistd.h>

#if defined(__GLIBC__) && !defined(__USE_XOPEN2K8)
#error "tetrig_shm.h needs POSIX.1-2008 declarations: include it before any system header, or compile with -D_POSIX_C_SOURCE=200809L"
#endif
#if !defined(__GNUC__) && !defined(__clang__)
#error "tetrig_shm.h needs the GCC/Clang __atomic builtins"
#endif
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "tetrig_shm.h: the segment layout is little-endian (host order of the producer)"
#endif

#ifdef __cplusplus
#define TETRIG_SHM_PTR(type, expr) (reinterpret_cast<type>(expr))
#define TETRIG_SHM_CONV(type, expr) (static_cast<type>(expr))
#define TETRIG_SHM_STATIC_ASSERT(cond, msg) static_assert(cond, msg)
#else
#define TETRIG_SHM_PTR(type, expr) ((type)(expr))
#define TETRIG_SHM_CONV(type, expr) ((type)(expr))
#if defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L
#define TETRIG_SHM_STATIC_ASSERT(cond, msg) _Static_assert(cond, msg)
#else /* C99: a negative array size stops the compilation */
#define TETRIG_SHM_JOIN2(a, b) a##b
#define TETRIG_SHM_JOIN(a, b) TETRIG_SHM_JOIN2(a, b)
#define TETRIG_SHM_STATIC_ASSERT(cond, msg) \
  typedef char TETRIG_SHM_JOIN(tetrig_shm_static_assert_, __LINE__)[(cond) ? 1 : -1]
#endif
#endif

/* ---- constants ---------------------------------------------------------------------------- */

/* The bytes "TETRIGSM" read as a little-endian uint64. */
#define TETRIG_SHM_MAGIC UINT64_C(0x4D53474952544554)
#define TETRIG_SHM_VERSION_MAJOR 1u /* a reader refuses any other major version */
#define TETRIG_SHM_VERSION_MINOR 1u /* newer minors only append fields in reserved space */
#define TETRIG_SHM_HEADER_SIZE 256u
#define TETRIG_SHM_ALIGNMENT 64u    /* every array starts on a 64-byte boundary */
#define TETRIG_SHM_MIN_SLOTS 3u
#define TETRIG_SHM_MAX_SLOTS 64u
#define TETRIG_SHM_SLOT_HEADER_SIZE 128u /* sequence + frame info, before the positions */
#define TETRIG_SHM_NAME_MAX 255u          /* longest segment name, '/' included */

/* TetrigShmHeader.flags */
#define TETRIG_SHM_HAS_NORMALS 0x1u
#define TETRIG_SHM_HAS_MARKER_POSITIONS 0x2u /* 1.1: per-slot marker positions and states */

/* Per-marker state byte of the marker block (1.1), one per marker in label order. */
#define TETRIG_SHM_MARKER_UNKNOWN 0u   /* no target (e.g. a non-finite one was replaced by 0) */
#define TETRIG_SHM_MARKER_MEASURED 1u  /* the measurement itself */
#define TETRIG_SHM_MARKER_PREDICTED 2u /* no measurement this frame: predicted (occluded) */
#define TETRIG_SHM_MARKER_BLENDED 3u   /* measured again, blending from the prediction back */
#define TETRIG_SHM_MARKER_REJECTED 4u  /* measured, but the sample was implausible (rejected): predicted instead */

/* TetrigShmHeader.state (the producer's state; 0 only before the first heartbeat) */
#define TETRIG_SHM_STATE_RUNNING 1u      /* frames arrive from the source */
#define TETRIG_SHM_STATE_STALE_SOURCE 2u /* producer alive, no new source frame: pose held */
#define TETRIG_SHM_STATE_STOPPED 3u      /* clean shutdown: no more frames ever */

/* TetrigShmFrameInfo.flags */
#define TETRIG_SHM_FRAME_STALE_SOURCE 0x1u      /* reserved: tetrig run publishes no frame while its source */
                                                /* is silent (the header's state is STALE_SOURCE instead) */
#define TETRIG_SHM_FRAME_POSE_HELD 0x2u         /* every marker occluded: pose held */
#define TETRIG_SHM_FRAME_BUDGET_MISS 0x4u       /* iteration deadline hit before the count */
#define TETRIG_SHM_FRAME_MARKERS_PREDICTED 0x8u /* some marker targets were predicted */
#define TETRIG_SHM_FRAME_INPUT_REJECTED 0x10u   /* non-finite or absurd input was rejected */
#define TETRIG_SHM_FRAME_POSE_REJECTED 0x20u    /* the solved pose was non-finite or implausible: the last */
                                                /* good pose was published again */

/* Return codes of tetrig_shm_open / tetrig_shm_attach / tetrig_shm_read_latest. */
#define TETRIG_SHM_OK 0
#define TETRIG_SHM_NO_FRAME 1        /* read: nothing published yet */
#define TETRIG_SHM_BUSY 2            /* read: lapped by the writer max_attempts times in a row */
#define TETRIG_SHM_E_NOT_FOUND (-1)  /* no segment of that name (yet) */
#define TETRIG_SHM_E_NOT_READY (-2)  /* segment exists but is still being created (retry) */
#define TETRIG_SHM_E_MAGIC (-3)      /* not a tetrig segment */
#define TETRIG_SHM_E_VERSION (-4)    /* a major layout version this header does not know */
#define TETRIG_SHM_E_SIZE (-5)       /* sizes, counts or offsets inconsistent with the file */
#define TETRIG_SHM_E_ACCESS (-6)     /* permission denied (segments are 0600 by default) */
#define TETRIG_SHM_E_SYSTEM (-7)     /* another system error: see TetrigShmReader.error */
#define TETRIG_SHM_E_ARGUMENT (-8)   /* bad name, NULL reader or a buffer too small */
#define TETRIG_SHM_NO_MARKERS 3      /* read markers: the segment has no marker positions (a 1.0
                                        producer, no markers, or the producer left them out) */
#define TETRIG_SHM_E_OWNER (-9)      /* the segment belongs to another user than the one required
                                        (tetrig_shm_open: the reader's effective uid; see
                                        tetrig_shm_open_as); TetrigShmReader.owner_uid says whose */
#define TETRIG_SHM_E_MODE (-10)      /* the segment is writable by group or others: any such user
                                        could rewrite or truncate it under its readers */

/* tetrig_shm_producer_status() */
#define TETRIG_SHM_PRODUCER_ALIVE 0   /* pid alive and heartbeat fresh */
#define TETRIG_SHM_PRODUCER_STALE 1   /* pid alive, heartbeat older than the limit: hung/paused */
#define TETRIG_SHM_PRODUCER_STOPPED 2 /* state says stopped (clean shutdown) */
#define TETRIG_SHM_PRODUCER_DEAD 3    /* pid gone (or a zombie) without a clean stop: crashed */

/* tetrig_shm_name_status() */
#define TETRIG_SHM_NAME_SAME 0     /* the name still refers to the mapped segment */
#define TETRIG_SHM_NAME_REPLACED 1 /* the name refers to another segment (a new producer) */
#define TETRIG_SHM_NAME_GONE 2     /* the name was unlinked */

/* ---- layout ------------------------------------------------------------------------------- */

/* The segment header, at offset 0 (256 bytes). Bytes 0..95 (identity and live words) keep these
 * offsets in every future major version, so any reader can tell whose segment it is and whether
 * its producer lives. Fields are written once before `magic`, except the live words (state,
 * heartbeat_ns, latest_frame_id), which the producer updates with atomic stores. */
typedef struct TetrigShmHeader {
  uint64_t magic;             /*   0 TETRIG_SHM_MAGIC; stored last at creation (release) */
  uint16_t version_major;     /*   8 */
  uint16_t version_minor;     /*  10 */
  uint32_t header_size;       /*  12 bytes of this header (256 in 1.0) */
  uint64_t total_size;        /*  16 bytes of the whole segment (= file size) */
  uint64_t instance_id;       /*  24 random, non-zero, new for every producer run */
  int64_t start_unix_ns;      /*  32 CLOCK_REALTIME at creation */
  int64_t start_monotonic_ns; /*  40 CLOCK_MONOTONIC at creation */
  int32_t producer_pid;       /*  48 written first at creation (before the static data) */
  uint32_t flags;             /*  52 TETRIG_SHM_HAS_NORMALS */
  uint64_t reserved0;         /*  56 */
  /* live words (own cache line) */
  uint32_t state;             /*  64 TETRIG_SHM_STATE_* (atomic) */
  uint32_t reserved1;         /*  68 */
  int64_t heartbeat_ns;       /*  72 CLOCK_MONOTONIC of the last commit or heartbeat (atomic) */
  uint64_t latest_frame_id;   /*  80 newest complete frame, 0 = none yet (atomic, release) */
  uint64_t reserved2[5];      /*  88 */
  /* geometry */
  uint32_t vertex_count;      /* 128 */
  uint32_t triangle_count;    /* 132 */
  uint32_t slot_count;        /* 136 3..64 */
  uint32_t marker_count;      /* 140 number of marker labels (0 = none) */
  uint32_t rig_name_length;   /* 144 bytes, without the terminating NUL */
  uint32_t reserved3;         /* 148 */
  uint64_t triangles_offset;      /* 152 uint32 x 3 per triangle */
  uint64_t rest_positions_offset; /* 160 float x 3 per vertex */
  uint64_t rig_name_offset;       /* 168 UTF-8, NUL-terminated */
  uint64_t marker_labels_offset;  /* 176 marker_count NUL-terminated strings, back to back */
  uint64_t marker_labels_size;    /* 184 bytes of the label block (NULs included) */
  uint64_t slots_offset;          /* 192 first slot */
  uint64_t slot_stride;           /* 200 bytes from one slot to the next (multiple of 64) */
  uint64_t slot_positions_offset; /* 208 from the slot start: float x 3 per vertex */
  uint64_t slot_normals_offset;   /* 216 from the slot start: float x 3 per vertex, 0 = none */
  /* 1.1 (0 in 1.0 segments; read only when version_minor >= 1 and TETRIG_SHM_HAS_MARKER_POSITIONS) */
  uint64_t slot_marker_positions_offset; /* 224 from the slot start: float x 3 per marker, rig units */
  uint64_t slot_marker_states_offset;    /* 232 from the slot start: uint8 per marker (TETRIG_SHM_MARKER_*) */
  uint64_t reserved4[2];                 /* 240 */
} TetrigShmHeader;

/* Per-frame information, inside each slot at offset 16 (80 bytes). Times are nanoseconds of
 * CLOCK_MONOTONIC, except device_ns (the device's own clock, 0 when unknown); 0 = not stamped. */
typedef struct TetrigShmFrameInfo {
  uint64_t frame_id;         /*  0 1, 2, 3, ... per producer instance; slot = (id-1) % slots */
  uint64_t source_frame;     /*  8 the source's frame counter */
  int32_t iterations;        /* 16 solver iterations run */
  uint32_t flags;            /* 20 TETRIG_SHM_FRAME_* */
  uint16_t occluded_markers; /* 24 markers without a measurement this frame */
  uint16_t reserved0;        /* 26 */
  uint32_t reserved1;        /* 28 */
  int64_t device_ns;         /* 32 capture time, device clock */
  int64_t receive_ns;        /* 40 frame received by the driver */
  int64_t taken_ns;          /* 48 frame taken by the solver */
  int64_t step_done_ns;      /* 56 deformation step done */
  int64_t pose_done_ns;      /* 64 pose transfer (fine positions) done */
  int64_t publish_ns;        /* 72 slot published (stamped by the writer's commit) */
} TetrigShmFrameInfo;

/* Slot: uint64 sequence at 0 (odd while written), 8 reserved bytes, TetrigShmFrameInfo at 16,
 * reserved to 128, then positions at slot_positions_offset, normals at slot_normals_offset and
 * (1.1) marker positions and states at slot_marker_positions_offset / slot_marker_states_offset. */
#define TETRIG_SHM_SLOT_SEQUENCE_OFFSET 0u
#define TETRIG_SHM_SLOT_INFO_OFFSET 16u

TETRIG_SHM_STATIC_ASSERT(sizeof(TetrigShmHeader) == TETRIG_SHM_HEADER_SIZE, "header is 256 bytes");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, producer_pid) == 48, "pid at 48");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, state) == 64, "state at 64");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, heartbeat_ns) == 72, "heartbeat at 72");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, latest_frame_id) == 80, "latest at 80");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, vertex_count) == 128, "counts at 128");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, triangles_offset) == 152, "offsets at 152");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, slot_normals_offset) == 216, "normals at 216");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, slot_marker_positions_offset) == 224, "markers at 224");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmHeader, slot_marker_states_offset) == 232, "marker states at 232");
TETRIG_SHM_STATIC_ASSERT(sizeof(TetrigShmFrameInfo) == 80, "frame info is 80 bytes");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmFrameInfo, device_ns) == 32, "device_ns at 32");
TETRIG_SHM_STATIC_ASSERT(offsetof(TetrigShmFrameInfo, publish_ns) == 72, "publish_ns at 72");
TETRIG_SHM_STATIC_ASSERT(TETRIG_SHM_SLOT_INFO_OFFSET + sizeof(TetrigShmFrameInfo) <= TETRIG_SHM_SLOT_HEADER_SIZE,
                         "frame info fits the slot header");

/* ---- reader ------------------------------------------------------------------------------- */

/* The reader trusts nothing it reads from the segment after the checks at open: whoever can
 * write the segment (its owner) may rewrite any byte at any time. tetrig_shm_attach copies the
 * whole header into `header_copy` (relaxed word loads after the magic's acquire load), checks the
 * copy, and from then on every count, offset, stride and flag comes from the copy only; the live
 * header is read again only for its live words (state, heartbeat_ns, latest_frame_id), which are
 * never used as a divisor, an index or an offset unchecked (latest_frame_id is reduced modulo the
 * copied slot count, and a slot's frame id and sequence only decide whether a copy is kept). */
typedef struct TetrigShmReader {
  const unsigned char* base;      /* the segment (read-only) */
  uint64_t size;                  /* bytes of the segment (the mapping's length) */
  void* mapping;                  /* what tetrig_shm_open mapped (NULL when attached) */
  const TetrigShmHeader* header;  /* == base: the LIVE header, which the segment's owner can rewrite;
                                     read static fields from header_copy, not from here */
  int owns_mapping;               /* 1: opened by name (close unmaps); 0: attached */
  int error;                      /* errno of the last TETRIG_SHM_E_SYSTEM / E_ACCESS */
  uint64_t instance_id;           /* copied at open */
  int32_t producer_pid;           /* copied at open */
  uint64_t file_device;           /* st_dev / st_ino of the mapped object (name_status) */
  uint64_t file_inode;
  char name[TETRIG_SHM_NAME_MAX + 1];
  int max_attempts;               /* read_latest tries before TETRIG_SHM_BUSY (default 64) */
  uint64_t last_frame_id;         /* frame id of the last successful read (0 = none) */
  uint64_t reads;                 /* successful reads */
  uint64_t retries;               /* attempts discarded: slot being written or overwritten */
  uint64_t busy;                  /* reads that gave up (TETRIG_SHM_BUSY) */
  TetrigShmHeader header_copy;    /* the header as copied and checked at open: the only source of
                                     the static fields (its live words are the values at open) */
  uid_t owner_uid;                /* the segment's owner (st_uid; set by tetrig_shm_open, also when
                                     it returns TETRIG_SHM_E_OWNER or E_MODE) */
  uint32_t mode;                  /* the segment's permission bits (st_mode & 07777), likewise */
} TetrigShmReader;

/* Text for a TETRIG_SHM_* return code. */
static inline const char* tetrig_shm_status_string(int code) {
  switch (code) {
    case TETRIG_SHM_OK: return "ok";
    case TETRIG_SHM_NO_FRAME: return "no frame published yet";
    case TETRIG_SHM_BUSY: return "writer lapped the reader on every attempt";
    case TETRIG_SHM_NO_MARKERS: return "segment has no marker positions (layout 1.0, no markers, or left out)";
    case TETRIG_SHM_E_NOT_FOUND: return "no such shared-memory segment";
    case TETRIG_SHM_E_NOT_READY: return "segment is still being created";
    case TETRIG_SHM_E_MAGIC: return "not a tetrig segment (bad magic)";
    case TETRIG_SHM_E_VERSION: return "unsupported layout major version";
    case TETRIG_SHM_E_SIZE: return "segment sizes or offsets are inconsistent";
    case TETRIG_SHM_E_ACCESS: return "permission denied";
    case TETRIG_SHM_E_SYSTEM: return "system error";
    case TETRIG_SHM_E_ARGUMENT: return "invalid argument";
    case TETRIG_SHM_E_OWNER: return "segment is owned by another user";
    case TETRIG_SHM_E_MODE: return "segment is writable by group or others";
    default: return "unknown status";
  }
}

/* CLOCK_MONOTONIC in nanoseconds: the clock of every TetrigShmFrameInfo time but device_ns. */
static inline int64_t tetrig_shm_now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return TETRIG_SHM_CONV(int64_t, ts.tv_sec) * INT64_C(1000000000) + TETRIG_SHM_CONV(int64_t, ts.tv_nsec);
}

/* Copies `bytes` (a multiple of 4) from the 8-byte aligned segment address `src` into `dst` (any
 * alignment) with relaxed atomic 8-byte loads (4-byte for the tail). */
static inline void tetrig_shm_load_words(void* dst, const void* src, uint64_t bytes) {
  const uint64_t* s = TETRIG_SHM_PTR(const uint64_t*, src);
  unsigned char* d = TETRIG_SHM_PTR(unsigned char*, dst);
  const uint64_t n = bytes / 8u;
  uint64_t i;
  for (i = 0; i < n; ++i) {
    const uint64_t w = __atomic_load_n(s + i, __ATOMIC_RELAXED);
    memcpy(d + 8u * i, &w, 8u);
  }
  if ((bytes & 7u) != 0u) {
    const uint32_t w = __atomic_load_n(TETRIG_SHM_PTR(const uint32_t*, s + n), __ATOMIC_RELAXED);
    memcpy(d + 8u * n, &w, 4u);
  }
}

static inline int tetrig_shm_internal_range_ok(uint64_t offset, uint64_t bytes, uint64_t total, int aligned) {
  if (aligned && (offset % TETRIG_SHM_ALIGNMENT) != 0u) return 0;
  return offset >= TETRIG_SHM_HEADER_SIZE && offset <= total && bytes <= total - offset;
}

/* 1 when the array of `bytes` bytes at `offset` from a slot's start lies inside a slot of `stride`
 * bytes, past the slot header, 64-byte aligned. */
static inline int tetrig_shm_internal_slot_range_ok(uint64_t offset, uint64_t bytes, uint64_t stride) {
  return offset % TETRIG_SHM_ALIGNMENT == 0u && offset >= TETRIG_SHM_SLOT_HEADER_SIZE && offset <= stride &&
         bytes <= stride - offset;
}

/* 1 when [a, a + a_bytes) and [b, b + b_bytes) do not overlap (both inside one slot: no overflow). */
static inline int tetrig_shm_internal_disjoint(uint64_t a, uint64_t a_bytes, uint64_t b, uint64_t b_bytes) {
  return a + a_bytes <= b || b + b_bytes <= a;
}

/* Validates a mapping of `size` bytes that holds a segment and fills `reader` (no copy of the
 * data: the reader points into the mapping, which must stay mapped until tetrig_shm_close). Used
 * by tetrig_shm_open; also for callers that map the segment themselves. Loads the magic (acquire;
 * 0 means still being created), copies the whole header into reader->header_copy and checks the
 * copy: major version, header and total size against `size`, counts, every offset, alignment and
 * range, the slot arrays inside a slot and disjoint, the strings' terminators and every triangle
 * index < vertex count. Afterwards the reader uses only the copy's static fields (see
 * TetrigShmReader). The mapping must be 64-byte aligned (mmap gives page alignment). */
static inline int tetrig_shm_attach(TetrigShmReader* reader, const void* base, uint64_t size) {
  TetrigShmHeader hc; /* the copy: checked here, the only source of static fields afterwards */
  const TetrigShmHeader* h;
  uint64_t magic, v, slot_end, label_bytes, position_bytes;
  uint32_t labels_found;
  int with_normals, with_markers;
  const unsigned char* bytes = TETRIG_SHM_PTR(const unsigned char*, base);
  if (reader == NULL || base == NULL) return TETRIG_SHM_E_ARGUMENT;
  memset(reader, 0, sizeof *reader);
  if (size < TETRIG_SHM_HEADER_SIZE) return TETRIG_SHM_E_NOT_READY;
  h = TETRIG_SHM_PTR(const TetrigShmHeader*, base);
  magic = __atomic_load_n(&h->magic, __ATOMIC_ACQUIRE); /* pairs with the producer's release */
  if (magic == 0u) return TETRIG_SHM_E_NOT_READY;
  if (magic != TETRIG_SHM_MAGIC) return TETRIG_SHM_E_MAGIC;
  tetrig_shm_load_words(&hc, h, sizeof hc);
  if (hc.magic != TETRIG_SHM_MAGIC) return TETRIG_SHM_E_MAGIC; /* rewritten meanwhile */
  if (hc.version_major != TETRIG_SHM_VERSION_MAJOR) return TETRIG_SHM_E_VERSION;
  if (hc.header_size < TETRIG_SHM_HEADER_SIZE || hc.header_size % TETRIG_SHM_ALIGNMENT != 0u || hc.total_size != size ||
      hc.total_size < hc.header_size) {
    return TETRIG_SHM_E_SIZE;
  }
  if (hc.vertex_count == 0u || hc.slot_count < TETRIG_SHM_MIN_SLOTS || hc.slot_count > TETRIG_SHM_MAX_SLOTS) {
    return TETRIG_SHM_E_SIZE;
  }
  v = hc.vertex_count;
  position_bytes = v * 12u;
  if (!tetrig_shm_internal_range_ok(hc.triangles_offset, TETRIG_SHM_CONV(uint64_t, hc.triangle_count) * 12u, size, 1) ||
      !tetrig_shm_internal_range_ok(hc.rest_positions_offset, position_bytes, size, 1) ||
      !tetrig_shm_internal_range_ok(hc.rig_name_offset, TETRIG_SHM_CONV(uint64_t, hc.rig_name_length) + 1u, size, 1) ||
      !tetrig_shm_internal_range_ok(hc.marker_labels_offset, hc.marker_labels_size, size, 1)) {
    return TETRIG_SHM_E_SIZE;
  }
  if (bytes[hc.rig_name_offset + hc.rig_name_length] != 0u) return TETRIG_SHM_E_SIZE;
  /* labels: exactly marker_count NUL-terminated strings */
  labels_found = 0u;
  for (label_bytes = 0; label_bytes < hc.marker_labels_size; ++label_bytes) {
    if (bytes[hc.marker_labels_offset + label_bytes] == 0u) ++labels_found;
  }
  if (labels_found != hc.marker_count ||
      (hc.marker_labels_size > 0u && bytes[hc.marker_labels_offset + hc.marker_labels_size - 1u] != 0u)) {
    return TETRIG_SHM_E_SIZE;
  }
  /* slots: every array inside a slot, past its header, aligned, and no two arrays overlapping */
  if (hc.slot_stride % TETRIG_SHM_ALIGNMENT != 0u ||
      !tetrig_shm_internal_slot_range_ok(hc.slot_positions_offset, position_bytes, hc.slot_stride)) {
    return TETRIG_SHM_E_SIZE;
  }
  with_normals = (hc.flags & TETRIG_SHM_HAS_NORMALS) != 0u;
  if (with_normals) {
    if (!tetrig_shm_internal_slot_range_ok(hc.slot_normals_offset, position_bytes, hc.slot_stride) ||
        !tetrig_shm_internal_disjoint(hc.slot_positions_offset, position_bytes, hc.slot_normals_offset, position_bytes)) {
      return TETRIG_SHM_E_SIZE;
    }
  } else if (hc.slot_normals_offset != 0u) {
    return TETRIG_SHM_E_SIZE;
  }
  /* 1.1 marker block: checked only when the segment says it has one (a 1.0 segment never does) */
  with_markers = hc.version_minor >= 1u && (hc.flags & TETRIG_SHM_HAS_MARKER_POSITIONS) != 0u;
  if (with_markers) {
    const uint64_t m = hc.marker_count;
    const uint64_t mp = hc.slot_marker_positions_offset, ms = hc.slot_marker_states_offset;
    const uint64_t state_bytes = (m + 3u) / 4u * 4u;
    if (m == 0u || !tetrig_shm_internal_slot_range_ok(mp, m * 12u, hc.slot_stride) ||
        !tetrig_shm_internal_slot_range_ok(ms, state_bytes, hc.slot_stride) ||
        !tetrig_shm_internal_disjoint(mp, m * 12u, ms, state_bytes) ||
        !tetrig_shm_internal_disjoint(mp, m * 12u, hc.slot_positions_offset, position_bytes) ||
        !tetrig_shm_internal_disjoint(ms, state_bytes, hc.slot_positions_offset, position_bytes) ||
        (with_normals && (!tetrig_shm_internal_disjoint(mp, m * 12u, hc.slot_normals_offset, position_bytes) ||
                          !tetrig_shm_internal_disjoint(ms, state_bytes, hc.slot_normals_offset, position_bytes)))) {
      return TETRIG_SHM_E_SIZE;
    }
  }
  if (hc.slot_stride == 0u || hc.slot_stride > size / hc.slot_count) return TETRIG_SHM_E_SIZE;
  slot_end = hc.slot_stride * hc.slot_count;
  if (!tetrig_shm_internal_range_ok(hc.slots_offset, slot_end, size, 1)) return TETRIG_SHM_E_SIZE;
  /* triangle indices */
  {
    const uint32_t* tri = TETRIG_SHM_PTR(const uint32_t*, bytes + hc.triangles_offset);
    const uint64_t n = TETRIG_SHM_CONV(uint64_t, hc.triangle_count) * 3u;
    uint64_t i;
    for (i = 0; i < n; ++i) {
      if (tri[i] >= hc.vertex_count) return TETRIG_SHM_E_SIZE;
    }
  }
  reader->base = bytes;
  reader->size = size;
  reader->header = h;
  reader->header_copy = hc;
  reader->instance_id = hc.instance_id;
  reader->producer_pid = hc.producer_pid;
  reader->max_attempts = 64;
  reader->last_frame_id = 0u;
  reader->reads = 0u;
  reader->retries = 0u;
  reader->busy = 0u;
  return TETRIG_SHM_OK;
}

/* Opens the segment `name` ("/name", at most 255 bytes) read-only, requiring that it belongs to
 * the user `owner`: shm_open + fstat; another owner -> TETRIG_SHM_E_OWNER, write permission for
 * group or others -> TETRIG_SHM_E_MODE (in both cases reader->owner_uid and reader->mode say what
 * was found); then mmap and tetrig_shm_attach. On failure nothing stays open and the reader is
 * zeroed (safe to close) but for `error`, `owner_uid` and `mode`. TETRIG_SHM_E_NOT_FOUND /
 * E_NOT_READY are normal while the producer starts: retry. */
static inline int tetrig_shm_open_as(TetrigShmReader* reader, const char* name, uid_t owner) {
  int fd, rc;
  struct stat st;
  void* map;
  size_t len;
  if (reader == NULL) return TETRIG_SHM_E_ARGUMENT;
  memset(reader, 0, sizeof *reader);
  if (name == NULL || name[0] != '/' || strlen(name) > TETRIG_SHM_NAME_MAX) return TETRIG_SHM_E_ARGUMENT;
  fd = shm_open(name, O_RDONLY | O_CLOEXEC, 0);
  if (fd < 0) {
    reader->error = errno;
    if (errno == ENOENT) return TETRIG_SHM_E_NOT_FOUND;
    if (errno == EACCES || errno == EPERM) return TETRIG_SHM_E_ACCESS;
    if (errno == EINVAL || errno == ENAMETOOLONG) return TETRIG_SHM_E_ARGUMENT;
    return TETRIG_SHM_E_SYSTEM;
  }
  if (fstat(fd, &st) != 0) {
    reader->error = errno;
    close(fd);
    return TETRIG_SHM_E_SYSTEM;
  }
  reader->owner_uid = st.st_uid;
  reader->mode = TETRIG_SHM_CONV(uint32_t, st.st_mode & 07777);
  if (st.st_uid != owner) { /* someone else's object under the name (a squatter, or another user's producer) */
    close(fd);
    return TETRIG_SHM_E_OWNER;
  }
  if ((st.st_mode & (S_IWGRP | S_IWOTH)) != 0) { /* others could rewrite or truncate it under us */
    close(fd);
    return TETRIG_SHM_E_MODE;
  }
  if (st.st_size < TETRIG_SHM_CONV(off_t, TETRIG_SHM_HEADER_SIZE)) {
    close(fd);
    return TETRIG_SHM_E_NOT_READY; /* created, not yet sized */
  }
  len = TETRIG_SHM_CONV(size_t, st.st_size);
  map = mmap(NULL, len, PROT_READ, MAP_SHARED, fd, 0);
  close(fd);
  if (map == MAP_FAILED) {
    reader->error = errno;
    return TETRIG_SHM_E_SYSTEM;
  }
  rc = tetrig_shm_attach(reader, map, TETRIG_SHM_CONV(uint64_t, len));
  if (rc != TETRIG_SHM_OK) {
    munmap(map, len);
    memset(reader, 0, sizeof *reader);
    reader->owner_uid = st.st_uid;
    reader->mode = TETRIG_SHM_CONV(uint32_t, st.st_mode & 07777);
    return rc;
  }
  reader->owns_mapping = 1;
  reader->mapping = map;
  reader->file_device = TETRIG_SHM_CONV(uint64_t, st.st_dev);
  reader->file_inode = TETRIG_SHM_CONV(uint64_t, st.st_ino);
  reader->owner_uid = st.st_uid;
  reader->mode = TETRIG_SHM_CONV(uint32_t, st.st_mode & 07777);
  memcpy(reader->name, name, strlen(name) + 1u);
  return TETRIG_SHM_OK;
}

/* tetrig_shm_open_as with the reader's own effective uid as the required owner: a segment made by
 * another user (or a squatter holding the name) is refused with TETRIG_SHM_E_OWNER. */
static inline int tetrig_shm_open(TetrigShmReader* reader, const char* name) {
  return tetrig_shm_open_as(reader, name, geteuid());
}

/* Unmaps (when opened by name) and zeroes the reader. Safe on a zeroed or failed reader. */
static inline void tetrig_shm_close(TetrigShmReader* reader) {
  if (reader == NULL) return;
  if (reader->owns_mapping && reader->mapping != NULL) munmap(reader->mapping, TETRIG_SHM_CONV(size_t, reader->size));
  memset(reader, 0, sizeof *reader);
}

/* ---- static data (from the header copied and checked at open) ----
 * Counts and flags come from reader->header_copy. The pointer accessors (triangles, rest
 * positions, rig name, labels) point into the segment, whose owner could rewrite those bytes after
 * the checks at open: before indexing an array with triangle indices, copy them with
 * tetrig_shm_copy_triangles (which checks the copy); for text, tetrig_shm_copy_rig_name and
 * tetrig_shm_copy_marker_label give a copy that is always terminated. */
static inline uint32_t tetrig_shm_vertex_count(const TetrigShmReader* r) { return r->header_copy.vertex_count; }
static inline uint32_t tetrig_shm_triangle_count(const TetrigShmReader* r) { return r->header_copy.triangle_count; }
static inline uint32_t tetrig_shm_slot_count(const TetrigShmReader* r) { return r->header_copy.slot_count; }
static inline int tetrig_shm_has_normals(const TetrigShmReader* r) {
  return (r->header_copy.flags & TETRIG_SHM_HAS_NORMALS) != 0u;
}
/* triangle_count x 3 vertex indices (counter-clockwise seen from outside), in the segment. */
static inline const uint32_t* tetrig_shm_triangles(const TetrigShmReader* r) {
  return TETRIG_SHM_PTR(const uint32_t*, r->base + r->header_copy.triangles_offset);
}
/* Copies the triangle_count x 3 indices into `out` (`out_len` entries) and checks the copy: every
 * index < vertex_count. TETRIG_SHM_OK, TETRIG_SHM_E_ARGUMENT (NULL reader or buffer too small:
 * nothing written) or TETRIG_SHM_E_SIZE (an index out of range: the segment was rewritten after
 * open; `out` holds the bad copy). */
static inline int tetrig_shm_copy_triangles(const TetrigShmReader* r, uint32_t* out, size_t out_len) {
  const uint64_t n = r == NULL ? 0u : TETRIG_SHM_CONV(uint64_t, r->header_copy.triangle_count) * 3u;
  uint64_t i;
  if (r == NULL || r->header == NULL || (n > 0u && out == NULL) || out_len < n) return TETRIG_SHM_E_ARGUMENT;
  if (n > 0u) memcpy(out, r->base + r->header_copy.triangles_offset, TETRIG_SHM_CONV(size_t, n) * 4u);
  for (i = 0; i < n; ++i) {
    if (out[i] >= r->header_copy.vertex_count) return TETRIG_SHM_E_SIZE;
  }
  return TETRIG_SHM_OK;
}
/* vertex_count x 3 floats: the rest pose, rig units. */
static inline const float* tetrig_shm_rest_positions(const TetrigShmReader* r) {
  return TETRIG_SHM_PTR(const float*, r->base + r->header_copy.rest_positions_offset);
}
/* The rig name in the segment (terminated when checked at open; see tetrig_shm_copy_rig_name). */
static inline const char* tetrig_shm_rig_name(const TetrigShmReader* r) {
  return TETRIG_SHM_PTR(const char*, r->base + r->header_copy.rig_name_offset);
}
/* Copies bytes [0, len) of the block at `offset` into `out` (`cap` > 0 bytes) up to the first NUL,
 * at most cap - 1 bytes, and terminates the copy. */
static inline void tetrig_shm_internal_copy_text(const TetrigShmReader* r, uint64_t offset, uint64_t len, char* out,
                                                 size_t cap) {
  const unsigned char* p = r->base + offset;
  size_t i = 0;
  while (i + 1u < cap && i < len && p[i] != 0u) {
    out[i] = TETRIG_SHM_CONV(char, p[i]);
    ++i;
  }
  out[i] = '\0';
}
/* Copies the rig name into `out` (`cap` > 0 bytes): at most cap - 1 bytes, always terminated,
 * never reading outside the name's block. TETRIG_SHM_OK or TETRIG_SHM_E_ARGUMENT. */
static inline int tetrig_shm_copy_rig_name(const TetrigShmReader* r, char* out, size_t cap) {
  if (r == NULL || r->header == NULL || out == NULL || cap == 0u) return TETRIG_SHM_E_ARGUMENT;
  tetrig_shm_internal_copy_text(r, r->header_copy.rig_name_offset, r->header_copy.rig_name_length, out, cap);
  return TETRIG_SHM_OK;
}
static inline uint32_t tetrig_shm_marker_count(const TetrigShmReader* r) { return r->header_copy.marker_count; }
/* 1 when every slot carries the markers' positions and states (layout 1.1 with the block; see
 * tetrig_shm_read_latest_markers), 0 for a 1.0 segment, a rig without markers, or a producer that
 * left them out. */
static inline int tetrig_shm_has_marker_positions(const TetrigShmReader* r) {
  return r->header_copy.version_minor >= 1u && (r->header_copy.flags & TETRIG_SHM_HAS_MARKER_POSITIONS) != 0u &&
         r->header_copy.marker_count > 0u;
}
/* Offset of label `index` in the segment and the bytes left in the label block from there, or 0
 * when index >= marker_count or the block no longer holds that many terminated labels. */
static inline uint64_t tetrig_shm_internal_label_offset(const TetrigShmReader* r, uint32_t index, uint64_t* left) {
  const uint64_t begin = r->header_copy.marker_labels_offset;
  const uint64_t end = begin + r->header_copy.marker_labels_size; /* checked inside the segment at open */
  uint64_t at = begin;
  uint32_t i = 0;
  if (index >= r->header_copy.marker_count) return 0u;
  while (i < index) {
    const void* nul;
    if (at >= end) return 0u;
    nul = memchr(r->base + at, 0, TETRIG_SHM_CONV(size_t, end - at));
    if (nul == NULL) return 0u;
    at = TETRIG_SHM_CONV(uint64_t, TETRIG_SHM_PTR(const unsigned char*, nul) - r->base) + 1u;
    ++i;
  }
  if (at >= end || memchr(r->base + at, 0, TETRIG_SHM_CONV(size_t, end - at)) == NULL) return 0u;
  *left = end - at;
  return at;
}
/* Label of marker `index` (< marker_count) in the segment, or NULL (also when the label block no
 * longer holds that many terminated labels). Walks the block, never past it: O(label bytes). */
static inline const char* tetrig_shm_marker_label(const TetrigShmReader* r, uint32_t index) {
  uint64_t left = 0u;
  const uint64_t at = tetrig_shm_internal_label_offset(r, index, &left);
  return at == 0u ? NULL : TETRIG_SHM_PTR(const char*, r->base + at);
}
/* Copies label `index` into `out` (`cap` > 0 bytes): at most cap - 1 bytes, always terminated,
 * never reading outside the label block. TETRIG_SHM_OK, TETRIG_SHM_E_ARGUMENT, or TETRIG_SHM_E_SIZE
 * when index >= marker_count or the block no longer holds the label (`out` is then ""). */
static inline int tetrig_shm_copy_marker_label(const TetrigShmReader* r, uint32_t index, char* out, size_t cap) {
  uint64_t left = 0u, at;
  if (r == NULL || r->header == NULL || out == NULL || cap == 0u) return TETRIG_SHM_E_ARGUMENT;
  out[0] = '\0';
  at = tetrig_shm_internal_label_offset(r, index, &left);
  if (at == 0u) return TETRIG_SHM_E_SIZE;
  tetrig_shm_internal_copy_text(r, at, left, out, cap);
  return TETRIG_SHM_OK;
}

/* ---- live words ---- */
static inline uint32_t tetrig_shm_state(const TetrigShmReader* r) {
  return __atomic_load_n(&r->header->state, __ATOMIC_ACQUIRE);
}
static inline int64_t tetrig_shm_heartbeat_ns(const TetrigShmReader* r) {
  return __atomic_load_n(&r->header->heartbeat_ns, __ATOMIC_ACQUIRE);
}
/* Newest complete frame id (0 = none yet): a cheap "is there a new frame?" poll. */
static inline uint64_t tetrig_shm_latest_frame_id(const TetrigShmReader* r) {
  return __atomic_load_n(&r->header->latest_frame_id, __ATOMIC_ACQUIRE);
}

/* Test hook: a statement run in the middle of each read attempt's copy (after the frame info,
 * before the positions), e.g. to wait until the writer has lapped the slot so that the copy is
 * really torn. Empty unless defined before this header is included; `reader` is the
 * TetrigShmReader* being read. */
#ifndef TETRIG_SHM_READ_WINDOW_HOOK
#define TETRIG_SHM_READ_WINDOW_HOOK(reader) ((void)0)
#endif

/* Copies `bytes` bytes (any count) of the 8-byte aligned segment address `src`, whose block is
 * padded to a multiple of 4 bytes, into `dst` with relaxed atomic loads; never writes past
 * dst + bytes. */
static inline void tetrig_shm_load_bytes(void* dst, const void* src, uint64_t bytes) {
  const uint64_t whole = bytes / 4u * 4u;
  unsigned char* d = TETRIG_SHM_PTR(unsigned char*, dst);
  tetrig_shm_load_words(d, src, whole);
  if (whole != bytes) {
    const uint32_t w = __atomic_load_n(TETRIG_SHM_PTR(const uint32_t*, TETRIG_SHM_PTR(const unsigned char*, src) + whole),
                                       __ATOMIC_RELAXED);
    memcpy(d + whole, &w, TETRIG_SHM_CONV(size_t, bytes - whole));
  }
}

/* The seqlock read behind tetrig_shm_read_latest and tetrig_shm_read_latest_markers (the marker
 * buffers are NULL for the former, and only used when the segment has the marker block). */
static inline int tetrig_shm_internal_read(TetrigShmReader* r, float* positions, size_t positions_len, float* normals,
                                           size_t normals_len, float* marker_positions, size_t marker_positions_len,
                                           uint8_t* marker_states, size_t marker_states_len, TetrigShmFrameInfo* info) {
  const TetrigShmHeader* h; /* the copy checked at open: counts, offsets, stride */
  const uint64_t* latest_word;
  uint64_t float_bytes, need, markers;
  int attempt, with_normals;
  if (r == NULL || r->header == NULL || r->header_copy.slot_count == 0u) return TETRIG_SHM_E_ARGUMENT;
  h = &r->header_copy;
  latest_word = &r->header->latest_frame_id; /* live, untrusted: only reduced modulo the slot count */
  need = TETRIG_SHM_CONV(uint64_t, h->vertex_count) * 3u;
  float_bytes = need * 4u;
  markers = h->marker_count;
  with_normals = normals != NULL && (h->flags & TETRIG_SHM_HAS_NORMALS) != 0u;
  if ((positions != NULL && positions_len < need) || (with_normals && normals_len < need)) return TETRIG_SHM_E_ARGUMENT;
  if ((marker_positions != NULL && marker_positions_len < markers * 3u) ||
      (marker_states != NULL && marker_states_len < markers)) {
    return TETRIG_SHM_E_ARGUMENT;
  }
  for (attempt = 0; attempt < r->max_attempts; ++attempt) {
    TetrigShmFrameInfo tmp;
    uint64_t seq1, seq2, slot_index;
    const unsigned char* slot;
    const uint64_t* seq;
    const uint64_t latest = __atomic_load_n(latest_word, __ATOMIC_ACQUIRE);
    if (latest == 0u) return TETRIG_SHM_NO_FRAME;
    slot_index = (latest - 1u) % h->slot_count;
    slot = r->base + h->slots_offset + slot_index * h->slot_stride;
    seq = TETRIG_SHM_PTR(const uint64_t*, slot + TETRIG_SHM_SLOT_SEQUENCE_OFFSET);
    seq1 = __atomic_load_n(seq, __ATOMIC_ACQUIRE);
    if ((seq1 & 1u) != 0u) {
      ++r->retries;
      continue;
    }
    tetrig_shm_load_words(&tmp, slot + TETRIG_SHM_SLOT_INFO_OFFSET, sizeof tmp);
    TETRIG_SHM_READ_WINDOW_HOOK(r);
    if (positions != NULL) tetrig_shm_load_words(positions, slot + h->slot_positions_offset, float_bytes);
    if (with_normals) tetrig_shm_load_words(normals, slot + h->slot_normals_offset, float_bytes);
    if (marker_positions != NULL) tetrig_shm_load_words(marker_positions, slot + h->slot_marker_positions_offset, markers * 12u);
    if (marker_states != NULL) tetrig_shm_load_bytes(marker_states, slot + h->slot_marker_states_offset, markers);
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    seq2 = __atomic_load_n(seq, __ATOMIC_RELAXED);
    /* tmp.frame_id > latest: the writer lapped us before seq1 (a complete newer frame, but
     * returning it could make the next read, which may still load the older latest, go back) */
    if (seq1 != seq2 || tmp.frame_id != latest) {
      ++r->retries;
      continue;
    }
    if (info != NULL) *info = tmp;
    r->last_frame_id = tmp.frame_id;
    ++r->reads;
    return TETRIG_SHM_OK;
  }
  ++r->busy;
  return TETRIG_SHM_BUSY;
}

/* Copies the newest complete frame: positions (vertex_count x 3 floats into `positions`, which
 * holds `positions_len` floats; NULL to skip), normals (same, only when the segment has normals;
 * otherwise `normals` is left untouched; NULL to skip) and its info (NULL to skip). Seqlock read:
 * load latest_frame_id, load the slot's sequence (acquire; odd = being written: retry), copy with
 * relaxed word loads, acquire fence, reload the sequence: unchanged means no write overlapped the
 * copy. Retries (counted in reader->retries) at most reader->max_attempts times in all; returns
 * TETRIG_SHM_OK, TETRIG_SHM_NO_FRAME, TETRIG_SHM_BUSY (buffers then hold garbage) or
 * TETRIG_SHM_E_ARGUMENT. The frame returned is the one latest_frame_id named when the successful
 * attempt began, so ids returned to one reader never go backwards. Wait-free apart from the
 * bounded retries; no system call, no allocation. */
static inline int tetrig_shm_read_latest(TetrigShmReader* r, float* positions, size_t positions_len,
                                         float* normals, size_t normals_len, TetrigShmFrameInfo* info) {
  return tetrig_shm_internal_read(r, positions, positions_len, normals, normals_len, NULL, 0u, NULL, 0u, info);
}

/* Layout 1.1: tetrig_shm_read_latest plus the same frame's marker block, in one seqlock read (the
 * mesh and the markers always belong to one frame). marker_positions: marker_count x 3 floats
 * (rig units, label order; `marker_positions_len` floats; NULL to skip); marker_states:
 * marker_count bytes, TETRIG_SHM_MARKER_* (NULL to skip). positions / normals / info as in
 * tetrig_shm_read_latest (each may be NULL). Returns TETRIG_SHM_NO_MARKERS, reading nothing, when
 * the segment has no marker positions (tetrig_shm_has_marker_positions() == 0: a 1.0 producer,
 * no markers, or the producer left them out): call tetrig_shm_read_latest instead. Otherwise the
 * codes of tetrig_shm_read_latest (E_ARGUMENT also when a marker buffer is too small). */
static inline int tetrig_shm_read_latest_markers(TetrigShmReader* r, float* positions, size_t positions_len,
                                                 float* normals, size_t normals_len, float* marker_positions,
                                                 size_t marker_positions_len, uint8_t* marker_states,
                                                 size_t marker_states_len, TetrigShmFrameInfo* info) {
  if (r == NULL || r->header == NULL) return TETRIG_SHM_E_ARGUMENT;
  if (!tetrig_shm_has_marker_positions(r)) return TETRIG_SHM_NO_MARKERS;
  return tetrig_shm_internal_read(r, positions, positions_len, normals, normals_len, marker_positions,
                                  marker_positions_len, marker_states, marker_states_len, info);
}

/* ---- producer liveness ---- */

/* 1 when process `pid` exists and is not a zombie, else 0. kill(pid, 0) (EPERM counts as alive:
 * the process exists under another user); on Linux also /proc/<pid>/stat, because a killed
 * producer whose parent has not reaped it yet is a zombie that kill() still finds. A pid is
 * only meaningful inside the producer's pid namespace. */
static inline int tetrig_shm_pid_alive(int32_t pid) {
  if (pid <= 0) return 0;
  if (kill(TETRIG_SHM_CONV(pid_t, pid), 0) != 0 && errno != EPERM) return 0;
#if defined(__linux__)
  {
    char path[64];
    char buf[512];
    ssize_t got;
    int fd;
    snprintf(path, sizeof path, "/proc/%ld/stat", TETRIG_SHM_CONV(long, pid));
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd >= 0) {
      got = read(fd, buf, sizeof buf - 1u);
      close(fd);
      if (got > 0) {
        const char* paren;
        buf[got] = '\0';
        paren = strrchr(buf, ')'); /* "pid (comm) S ..." ; comm may hold ')' */
        if (paren != NULL && paren[1] == ' ' && (paren[2] == 'Z' || paren[2] == 'X')) return 0;
      }
    } else if (errno == ENOENT) {
      return 0;
    }
  }
#endif
  return 1;
}

/* Age of the producer's heartbeat at `now_ns` (CLOCK_MONOTONIC), nanoseconds: INT64_MAX when
 * there is none (<= 0), 0 when it lies after `now_ns` (the word is the producer's to write: any
 * value is handled without overflow). */
static inline int64_t tetrig_shm_heartbeat_age_ns(const TetrigShmReader* r, int64_t now_ns) {
  const int64_t beat = tetrig_shm_heartbeat_ns(r);
  if (beat <= 0) return INT64_MAX;
  if (beat >= now_ns) return 0;
  return now_ns - beat; /* 0 < beat < now_ns: no overflow */
}

/* Tells a dead producer from a slow one: TETRIG_SHM_PRODUCER_STOPPED when the state says a clean
 * stop, DEAD when its pid is gone (or a zombie), STALE when the pid lives but the heartbeat is
 * older than `stale_after_ns` (hung, stopped by a debugger or SIGSTOP, starved), else ALIVE. A
 * producer whose source is stale still heartbeats (state TETRIG_SHM_STATE_STALE_SOURCE) and is
 * ALIVE here. The producer heartbeats with every frame and at least every few hundred ms while
 * idle, so a limit of about 1 s suits. */
static inline int tetrig_shm_producer_status(const TetrigShmReader* r, int64_t stale_after_ns) {
  if (tetrig_shm_state(r) == TETRIG_SHM_STATE_STOPPED) return TETRIG_SHM_PRODUCER_STOPPED;
  if (!tetrig_shm_pid_alive(r->producer_pid)) return TETRIG_SHM_PRODUCER_DEAD;
  if (tetrig_shm_heartbeat_age_ns(r, tetrig_shm_now_ns()) > stale_after_ns) return TETRIG_SHM_PRODUCER_STALE;
  return TETRIG_SHM_PRODUCER_ALIVE;
}

/* Whether the reader's name still refers to the segment it mapped: TETRIG_SHM_NAME_SAME,
 * _REPLACED (a new producer created a new segment under the name: close and open again, then
 * compare instance_id) or _GONE (unlinked: clean stop). Only for readers opened by name
 * (returns TETRIG_SHM_E_ARGUMENT otherwise). */
static inline int tetrig_shm_name_status(const TetrigShmReader* r) {
  struct stat st;
  int fd, rc;
  if (r == NULL || !r->owns_mapping) return TETRIG_SHM_E_ARGUMENT;
  fd = shm_open(r->name, O_RDONLY | O_CLOEXEC, 0);
  if (fd < 0) return errno == ENOENT ? TETRIG_SHM_NAME_GONE : TETRIG_SHM_E_SYSTEM;
  rc = fstat(fd, &st);
  close(fd);
  if (rc != 0) return TETRIG_SHM_E_SYSTEM;
  return (TETRIG_SHM_CONV(uint64_t, st.st_dev) == r->file_device && TETRIG_SHM_CONV(uint64_t, st.st_ino) == r->file_inode)
             ? TETRIG_SHM_NAME_SAME
             : TETRIG_SHM_NAME_REPLACED;
}

/* ---- latency helpers (nanoseconds; -1 when a time is unknown or the order is wrong) ---- */
static inline int64_t tetrig_shm_interval_ns(int64_t from_ns, int64_t to_ns) {
  return (from_ns > 0 && to_ns > 0 && to_ns >= from_ns) ? to_ns - from_ns : -1;
}
/* Driver receive -> publish: the runtime's whole latency for this frame. */
static inline int64_t tetrig_shm_receive_to_publish_ns(const TetrigShmFrameInfo* info) {
  return tetrig_shm_interval_ns(info->receive_ns, info->publish_ns);
}
/* Solver take -> publish: step plus pose transfer plus commit. */
static inline int64_t tetrig_shm_taken_to_publish_ns(const TetrigShmFrameInfo* info) {
  return tetrig_shm_interval_ns(info->taken_ns, info->publish_ns);
}
/* Publish -> `now_ns` (e.g. tetrig_shm_now_ns() right after the read): the consumer's delay. */
static inline int64_t tetrig_shm_publish_age_ns(const TetrigShmFrameInfo* info, int64_t now_ns) {
  return tetrig_shm_interval_ns(info->publish_ns, now_ns);
}

#endif /* TETRIG_SHM_H */
