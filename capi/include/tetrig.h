/* tetrig.h: the C API of the tetrig runtime, for engines and tools that bind C (Unity P/Invoke,
 * Unreal, Godot, Python ctypes, plain C). C99, no other header of tetrig needed; link libtetrig
 * (CMake: tetrig::c; pkg-config: tetrig). docs/embedding.md explains it with examples.
 *
 * A rig (tetrig_rig) is a rig file (`tetrig build-rig`) loaded into a live rig: bind the labels of
 * a marker source once, then give it one frame of marker positions at a time and get the deformed
 * fine mesh back in a buffer of yours. A clip (tetrig_clip) reads a C3D file's markers, for tools,
 * tests and offline playback.
 *
 * Conventions (every function):
 *  - Errors: functions return a tetrig_status (TETRIG_OK = 0) or, for counts and handles, -1 /
 *    NULL. A failure also sets this thread's error text (tetrig_last_error). No C++ exception
 *    ever crosses this boundary; a NULL handle, NULL buffer, wrong size or index is an error, never
 *    a crash.
 *  - Threads: a handle is used by one thread at a time (the caller serialises); different handles
 *    may be used on different threads at once.
 *  - Allocation: opening, binding and closing allocate (load time). tetrig_rig_process_frame and
 *    every query after tetrig_rig_bind_labels allocate nothing, take no lock and do no I/O.
 *  - Ownership: strings returned by the library (labels, units, error text) belong to it; they stay
 *    valid until the handle is closed (error text: until the next failure on the same thread).
 *    Buffers passed in belong to the caller and are not kept after the call returns.
 *  - Units: marker positions are millimetres in the source's own axes (as a C3D file or a device
 *    reports them); the rig maps them into its own space (tetrig_rig_unit, tetrig_rig_up_axis).
 *    Output vertex positions are in the rig's unit and axes, x0 y0 z0 x1 y1 z1 ...
 */
#ifndef TETRIG_H
#define TETRIG_H

#include <stddef.h>
#include <stdint.h>

#include "tetrig/version.h" /* TETRIG_VERSION_STRING: the version this header belongs to */

/* The library's exported functions (libtetrig is built with every other symbol hidden). */
#if defined(__GNUC__)
#define TETRIG_API __attribute__((visibility("default")))
#else
#define TETRIG_API
#endif
/* Seen from C++, no function of this header throws. */
#ifdef __cplusplus
#define TETRIG_NOEXCEPT noexcept
#else
#define TETRIG_NOEXCEPT
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* Status of a call. */
typedef enum tetrig_status {
  TETRIG_OK = 0,
  TETRIG_ERROR_INVALID_ARGUMENT = 1, /* a NULL handle or pointer, a negative or absurd number */
  TETRIG_ERROR_BUFFER_SIZE = 2,      /* a caller buffer's stated size is not what the call needs */
  TETRIG_ERROR_FILE = 3,             /* a file is missing, unreadable or not a valid rig / C3D file */
  TETRIG_ERROR_OUT_OF_RANGE = 4,     /* an index past the end (marker, frame) */
  TETRIG_ERROR_NOT_BOUND = 5,        /* a frame's marker count differs from the labels bound */
  TETRIG_ERROR_OUT_OF_MEMORY = 6,
  TETRIG_ERROR_INTERNAL = 7          /* anything else (a bug: please report it with the rig) */
} tetrig_status;

/* Bits of tetrig_frame_stats.flags (the same values as the C++ LiveFrameFlags). */
#define TETRIG_FRAME_POSE_HELD 0x01u          /* no rig marker measured: the last pose was kept (no step) */
#define TETRIG_FRAME_MARKERS_PREDICTED 0x02u  /* some rig markers were driven by their prediction */
#define TETRIG_FRAME_MARKERS_BLENDING 0x04u   /* some markers blend between prediction and measurement */
#define TETRIG_FRAME_DEADLINE_HIT 0x08u       /* the budget stopped the iterations before max_iterations */
#define TETRIG_FRAME_TARGETS_REJECTED 0x10u   /* the solver refused the targets (kept the previous ones) */
#define TETRIG_FRAME_POSE_REJECTED 0x20u      /* the step gave an implausible pose: the last one was written */
#define TETRIG_FRAME_MARKERS_REJECTED 0x40u   /* some samples were implausible and treated as occluded */

/* What one frame did. Times in nanoseconds. */
typedef struct tetrig_frame_stats {
  uint64_t frames;                 /* frames processed by this rig so far, this one included */
  int32_t iterations;              /* solver iterations run (0 when the pose was held) */
  uint32_t flags;                  /* TETRIG_FRAME_* bits */
  double energy;                   /* the solver's energy after the last iteration */
  int64_t step_ns;                 /* the solver step (coarse level included) */
  int64_t pose_transfer_ns;        /* the fine mesh from the tet mesh (or the copy of a held pose) */
  int64_t total_ns;                /* the whole call */
  int32_t measured_markers;        /* rig markers measured in this frame */
  int32_t occluded_markers;        /* rig markers driven by their prediction (never-named ones too) */
  int32_t blending_markers;        /* rig markers blending in or out */
  int32_t unknown_markers;         /* frame markers whose label names no rig marker (ignored) */
  int32_t rejected_marker_samples; /* samples refused as non-finite, absurd or implausible */
} tetrig_frame_stats;

/* How a rig is opened. Initialise with tetrig_rig_options_init, then change fields. */
typedef struct tetrig_rig_options {
  uint32_t struct_size;      /* sizeof(tetrig_rig_options), set by tetrig_rig_options_init */
  int fast_settings;         /* 0 (default): the accurate solver settings, as `tetrig run` and `tetrig export`;
                                1: the fast ones (no temporal prediction, inversion guard or volume constraint) */
  double occlusion_blend_ms; /* blend time when a marker drops out or returns (default 150; 0: none) */
  int normals;               /* 1: also compute vertex normals (tetrig_rig_process_frame's normals buffer); default 0 */
} tetrig_rig_options;

typedef struct tetrig_rig tetrig_rig;   /* opaque: a loaded rig and its live solver state */
typedef struct tetrig_clip tetrig_clip; /* opaque: a C3D clip in memory */

/* ---- library ---- */

/* The library's version, "MAJOR.MINOR.PATCH" (TETRIG_VERSION_STRING of the build). Static string. */
TETRIG_API const char* tetrig_version(void) TETRIG_NOEXCEPT;

/* The text of the last failed call on this thread ("" if none failed yet): one line that says
 * what failed and why. Owned by the library; valid until the next failure on this thread. */
TETRIG_API const char* tetrig_last_error(void) TETRIG_NOEXCEPT;

/* Nanoseconds on the clock the runtime uses (CLOCK_MONOTONIC): for frame timestamps. */
TETRIG_API int64_t tetrig_now_ns(void) TETRIG_NOEXCEPT;

/* ---- rig: load ---- */

/* Default options (accurate settings, 150 ms blends, no normals). options may not be NULL. */
TETRIG_API void tetrig_rig_options_init(tetrig_rig_options* options) TETRIG_NOEXCEPT;

/* Loads a rig file (`tetrig build-rig`) and prepares its live solver (factorization, buffers: a
 * few milliseconds to a second). options: NULL for the defaults. Returns NULL on failure
 * (tetrig_last_error says why: missing file, not a rig, corrupt, bad options). Allocates. */
TETRIG_API tetrig_rig* tetrig_rig_open(const char* path, const tetrig_rig_options* options) TETRIG_NOEXCEPT;

/* Frees the rig. NULL is ignored. Not while another thread uses it. */
TETRIG_API void tetrig_rig_close(tetrig_rig* rig) TETRIG_NOEXCEPT;

/* ---- rig: what it holds (no allocation; -1 / NULL on a NULL handle or bad index) ---- */

TETRIG_API int32_t tetrig_rig_marker_count(const tetrig_rig* rig) TETRIG_NOEXCEPT;                 /* markers the rig is built for */
TETRIG_API const char* tetrig_rig_marker_label(const tetrig_rig* rig, int32_t i) TETRIG_NOEXCEPT;  /* label of rig marker i, e.g. "LFHD" */
TETRIG_API int32_t tetrig_rig_vertex_count(const tetrig_rig* rig) TETRIG_NOEXCEPT;    /* fine-mesh vertices (output positions: 3 floats each) */
TETRIG_API int32_t tetrig_rig_triangle_count(const tetrig_rig* rig) TETRIG_NOEXCEPT;  /* fine-mesh triangles */
TETRIG_API const char* tetrig_rig_unit(const tetrig_rig* rig) TETRIG_NOEXCEPT;        /* the rig's length unit: "m", "cm", "mm" or "mesh" */
TETRIG_API const char* tetrig_rig_up_axis(const tetrig_rig* rig) TETRIG_NOEXCEPT;     /* the rig's up axis: "y", "z", "-y", ... */

/* Copies the fine mesh's triangles: triangle_count*3 vertex indices (counter-clockwise seen from
 * outside). count: the int32_t entries `triangles` holds; must be at least triangle_count*3. */
TETRIG_API tetrig_status tetrig_rig_triangles(const tetrig_rig* rig, int32_t* triangles, size_t count) TETRIG_NOEXCEPT;

/* Copies the fine mesh's rest positions: vertex_count*3 floats (rig units). count as above. */
TETRIG_API tetrig_status tetrig_rig_rest_positions(const tetrig_rig* rig, float* positions, size_t count) TETRIG_NOEXCEPT;

/* ---- rig: bind a source ---- */

/* Binds a marker source's labels: labels[i] names the source's marker i, the i-th xyz of every
 * frame given to tetrig_rig_process_frame. A label matches a rig marker when equal, or when the parts
 * after their last ':' are equal ("meinard:LFHD" matches "LFHD"). NULL or "" names nothing.
 * count: at most 256. Replaces any earlier binding. Returns how many rig markers were bound (rig
 * markers no label names are predicted from the body every frame), or -1 on error. Allocates. */
TETRIG_API int32_t tetrig_rig_bind_labels(tetrig_rig* rig, const char* const* labels, size_t count) TETRIG_NOEXCEPT;

/* ---- rig: one frame ---- */

/* One frame of markers in, the deformed fine mesh out.
 *  markers_xyz:  marker_count*3 floats, x y z of the source's marker i (millimetres, the source's
 *                axes) in the order of the labels bound; a marker with a NaN coordinate is occluded.
 *                marker_count must equal the count last bound (0 with no markers: the pose is held).
 *  timestamp_ns: the frame's capture time in nanoseconds on any clock that does not run backwards
 *                (tetrig_now_ns, or the clip's time line); blends use it. 0: unknown (1/120 s a frame).
 *  max_iterations: solver iterations, at least 1 (3 is the live default).
 *  budget_ns:    > 0: stop iterating once this many nanoseconds passed since the call began (at
 *                least one iteration runs); 0: no time limit.
 *  positions:    vertex_count*3 floats written (rig units); positions_count: the floats it holds,
 *                at least vertex_count*3. Never a non-finite value.
 *  normals:      NULL, or vertex_count*3 floats of unit normals (needs options.normals);
 *                normals_count as for positions (ignored when normals is NULL).
 *  stats:        NULL, or the frame's statistics.
 * No allocation, lock, exception or I/O. On an error nothing is written and the rig is unchanged. */
TETRIG_API tetrig_status tetrig_rig_process_frame(tetrig_rig* rig, const float* markers_xyz, size_t marker_count,
                                                  int64_t timestamp_ns, int32_t max_iterations, int64_t budget_ns,
                                                  float* positions, size_t positions_count, float* normals,
                                                  size_t normals_count, tetrig_frame_stats* stats) TETRIG_NOEXCEPT;

/* Optional: the work the next frame would do first (the volume constraint's linearization at the
 * pose just written, and any after-publish iterations), done now, e.g. right after you copied the
 * positions out, so that it stays off the next frame's path. budget_ns > 0 bounds the iterations
 * (not the linearization); 0: no limit. The poses are the same bit for bit whether you call it or
 * not (when no budget cuts iterations). Returns the nanoseconds it took (0: nothing was pending),
 * or -1 on error. No allocation. */
TETRIG_API int64_t tetrig_rig_prepare_next_frame(tetrig_rig* rig, int64_t budget_ns) TETRIG_NOEXCEPT;

/* The last frame's statistics (all zero before the first frame). */
TETRIG_API tetrig_status tetrig_rig_frame_stats(const tetrig_rig* rig, tetrig_frame_stats* stats) TETRIG_NOEXCEPT;

/* ---- clip: a C3D file's markers ---- */

/* Reads a C3D file (Intel, DEC or MIPS; integer or float) into memory: its physical markers, as
 * `tetrig run --clip` plays them (unlabelled and modelled points skipped; a sample at exactly
 * x = y = z = 0 with residual 0 is a gap). Returns NULL on failure (tetrig_last_error). Allocates. */
TETRIG_API tetrig_clip* tetrig_clip_open(const char* path) TETRIG_NOEXCEPT;
TETRIG_API void tetrig_clip_close(tetrig_clip* clip) TETRIG_NOEXCEPT;  /* NULL is ignored */

TETRIG_API int32_t tetrig_clip_marker_count(const tetrig_clip* clip) TETRIG_NOEXCEPT;                 /* markers per frame */
TETRIG_API const char* tetrig_clip_marker_label(const tetrig_clip* clip, int32_t i) TETRIG_NOEXCEPT;  /* as stored, e.g. "meinard:LFHD" */
TETRIG_API int64_t tetrig_clip_frame_count(const tetrig_clip* clip) TETRIG_NOEXCEPT;
TETRIG_API double tetrig_clip_rate_hz(const tetrig_clip* clip) TETRIG_NOEXCEPT;                       /* 0 when the file has none */

/* Frame `frame` (0-based) of the clip: marker_count*3 floats into xyz (millimetres in the file's
 * axes, NaN for a gap), count: the floats xyz holds (at least marker_count*3), and the frame's time
 * on the clip's time line (frame * period, ns; 0 without a rate) into *timestamp_ns (may be NULL).
 * No allocation. */
TETRIG_API tetrig_status tetrig_clip_frame(const tetrig_clip* clip, int64_t frame, float* xyz, size_t count,
                                           int64_t* timestamp_ns) TETRIG_NOEXCEPT;

#ifdef __cplusplus
}
#endif

#endif /* TETRIG_H */
