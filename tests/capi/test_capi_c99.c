/* The C API from strict C99 (-std=c99 -pedantic -Werror -Wall -Wextra): tetrig.h alone, libtetrig.so.
 * Opens the real rig (the SMPL male rigged to HDM05's markers, built by the capi_rig fixture), binds
 * the HDM05 clip's labels, runs its first FRAMES frames with 3 iterations each and checks that the
 * outputs are finite, that the mesh follows the markers' motion, the statistics, and that bad calls
 * are refused with a status and a text. With OUT, writes the last frame's positions there (raw
 * floats), which the install test compares with an outside project's (tests/install).
 *
 * usage: test_capi_c99 SOURCE_DIR RIG [FRAMES [OUT]]
 * Exit 0: passed; 1: failed; 77: skipped (the data is absent, outside CI). */
#include "tetrig.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SKIP 77

static int failures = 0;

/* CHECK(condition, printf arguments...): counts and reports a failed check, goes on. */
#define CHECK(cond, ...)                                        \
  do {                                                          \
    if (!(cond)) {                                              \
      ++failures;                                               \
      printf("FAILED line %d: %s: ", __LINE__, #cond);          \
      printf(__VA_ARGS__);                                      \
      printf(" (last error: %s)\n", tetrig_last_error());       \
    }                                                           \
  } while (0)

static int fileExists(const char* path) {
  FILE* f = fopen(path, "rb");
  if (f == NULL) return 0;
  fclose(f);
  return 1;
}

static int runningInCi(void) {
  const char* ci = getenv("CI");
  return ci != NULL && (strcmp(ci, "true") == 0 || strcmp(ci, "1") == 0);
}

/* The data root: $TETRIG_DATA_DIR, else SOURCE_DIR/../shared/data (as tests/support/test_data.hpp). */
static void dataPath(char* out, size_t size, const char* source_dir, const char* relative) {
  const char* env = getenv("TETRIG_DATA_DIR");
  if (env != NULL && env[0] != '\0') {
    snprintf(out, size, "%s/%s", env, relative);
  } else {
    snprintf(out, size, "%s/../shared/data/%s", source_dir, relative);
  }
}

static int allFinite(const float* v, size_t n) {
  size_t i;
  for (i = 0; i < n; ++i) {
    if (!isfinite(v[i])) return 0;
  }
  return 1;
}

/* Largest distance between the same vertex in two poses. */
static double maxMove(const float* a, const float* b, size_t vertices) {
  double worst = 0.0;
  size_t v;
  for (v = 0; v < vertices; ++v) {
    const double dx = a[3 * v] - b[3 * v], dy = a[3 * v + 1] - b[3 * v + 1], dz = a[3 * v + 2] - b[3 * v + 2];
    const double d = sqrt(dx * dx + dy * dy + dz * dz);
    if (d > worst) worst = d;
  }
  return worst;
}

static void checkErrorsWithoutARig(const char* missing_path) {
  float buffer[3] = {0.0f, 0.0f, 0.0f};
  tetrig_rig* none = tetrig_rig_open(missing_path, NULL);
  CHECK(none == NULL, "a missing file opened");
  CHECK(strstr(tetrig_last_error(), "missing.rig") != NULL, "the error names the file");
  CHECK(tetrig_rig_open(NULL, NULL) == NULL, "a NULL path opened");
  CHECK(tetrig_rig_vertex_count(NULL) == -1, "NULL handle");
  CHECK(strstr(tetrig_last_error(), "NULL") != NULL, "the error says NULL");
  CHECK(tetrig_rig_marker_label(NULL, 0) == NULL, "NULL handle");
  CHECK(tetrig_rig_process_frame(NULL, buffer, 1, 0, 3, 0, buffer, 3, NULL, 0, NULL) == TETRIG_ERROR_INVALID_ARGUMENT, "NULL handle");
  CHECK(tetrig_clip_open(NULL) == NULL, "a NULL clip path opened");
  tetrig_rig_close(NULL);
  tetrig_clip_close(NULL);
}

int main(int argc, char** argv) {
  const char* source_dir;
  const char* rig_path;
  const char* out_path = NULL;
  long frames = 360;
  char clip_path[4096], missing_path[4096];
  tetrig_rig* rig;
  tetrig_clip* clip;
  int32_t rig_markers, clip_markers, bound, vertices, triangle_count, i;
  const char** labels;
  float *xyz, *x, *first, *rest, *sentinel;
  int32_t* triangles;
  size_t n;
  long f;
  int64_t t = 0;
  double marker_move = 0.0, mesh_move;
  tetrig_frame_stats stats;
  tetrig_rig_options options;

  if (argc < 3) {
    fprintf(stderr, "usage: test_capi_c99 SOURCE_DIR RIG [FRAMES [OUT]]\n");
    return 1;
  }
  source_dir = argv[1];
  rig_path = argv[2];
  if (argc > 3) frames = strtol(argv[3], NULL, 10);
  if (argc > 4) out_path = argv[4];
  dataPath(clip_path, sizeof clip_path, source_dir, "mocap/hdm05/HDM_mm_01-02_03_120.c3d");
  if (!fileExists(clip_path)) {
    if (runningInCi()) {
      printf("FAILED: test data missing in CI: %s (set TETRIG_DATA_DIR)\n", clip_path);
      return 1;
    }
    printf("SKIPPED: test data not found: %s (place ../shared/data beside the checkout or set TETRIG_DATA_DIR)\n", clip_path);
    return SKIP;
  }
  if (!fileExists(rig_path)) {
    printf("FAILED: the rig %s is missing (the capi_rig fixture builds it: tests/capi/make_rig.py)\n", rig_path);
    return 1;
  }

  /* The library is the version of its header. */
  CHECK(strcmp(tetrig_version(), TETRIG_VERSION_STRING) == 0, "tetrig_version() %s, header %s", tetrig_version(), TETRIG_VERSION_STRING);
  snprintf(missing_path, sizeof missing_path, "%s.missing.rig", rig_path);
  checkErrorsWithoutARig(missing_path);

  /* Open with the default options, explicitly. */
  tetrig_rig_options_init(&options);
  CHECK(options.struct_size == sizeof options && options.fast_settings == 0 && options.normals == 0, "default options");
  rig = tetrig_rig_open(rig_path, &options);
  clip = tetrig_clip_open(clip_path);
  if (rig == NULL || clip == NULL) {
    printf("FAILED: open: %s\n", tetrig_last_error());
    return 1;
  }
  CHECK(strcmp(tetrig_rig_unit(rig), "m") == 0, "the SMPL rig is in metres, not %s", tetrig_rig_unit(rig));
  CHECK(strcmp(tetrig_rig_up_axis(rig), "y") == 0, "the SMPL rig is y up, not %s", tetrig_rig_up_axis(rig));

  /* Markers: the rig's labels are the clip's without the subject prefix ("meinard:LFHD" -> "LFHD"). */
  rig_markers = tetrig_rig_marker_count(rig);
  clip_markers = tetrig_clip_marker_count(clip);
  CHECK(clip_markers == 41, "HDM05 has 41 physical markers, got %d", (int)clip_markers);
  CHECK(rig_markers > 30 && rig_markers <= clip_markers, "rig markers %d", (int)rig_markers);
  labels = (const char**)malloc(sizeof(const char*) * (size_t)clip_markers);
  for (i = 0; i < clip_markers; ++i) labels[i] = tetrig_clip_marker_label(clip, i);
  CHECK(strncmp(labels[0], "meinard:", 8) == 0, "clip label %s", labels[0]);
  for (i = 0; i < rig_markers; ++i) {
    const char* label = tetrig_rig_marker_label(rig, i);
    CHECK(label != NULL && strlen(label) > 0 && strchr(label, ':') == NULL, "rig marker %d label", (int)i);
  }
  CHECK(tetrig_rig_marker_label(rig, rig_markers) == NULL, "label past the end");
  bound = tetrig_rig_bind_labels(rig, labels, (size_t)clip_markers);
  CHECK(bound == rig_markers, "bound %d of %d rig markers", (int)bound, (int)rig_markers);

  /* The fine mesh: SMPL's 6890 vertices and 13776 triangles, indices in range. */
  vertices = tetrig_rig_vertex_count(rig);
  triangle_count = tetrig_rig_triangle_count(rig);
  CHECK(vertices == 6890, "vertices %d", (int)vertices);
  CHECK(triangle_count == 13776, "triangles %d", (int)triangle_count);
  n = (size_t)vertices * 3;
  triangles = (int32_t*)malloc(sizeof(int32_t) * (size_t)triangle_count * 3);
  CHECK(tetrig_rig_triangles(rig, triangles, (size_t)triangle_count * 3) == TETRIG_OK, "triangles");
  for (i = 0; i < triangle_count * 3; ++i) {
    if (triangles[i] < 0 || triangles[i] >= vertices) {
      CHECK(0, "triangle index %d = %d out of range", (int)i, (int)triangles[i]);
      break;
    }
  }

  xyz = (float*)malloc(sizeof(float) * (size_t)clip_markers * 3);
  x = (float*)malloc(sizeof(float) * n);
  first = (float*)malloc(sizeof(float) * n);
  rest = (float*)malloc(sizeof(float) * n);
  sentinel = (float*)malloc(sizeof(float) * n);
  CHECK(tetrig_rig_rest_positions(rig, rest, n) == TETRIG_OK, "rest positions");

  /* A buffer one float short is refused and left untouched. */
  for (i = 0; i < (int32_t)n; ++i) sentinel[i] = -1.0f;
  CHECK(tetrig_clip_frame(clip, 0, xyz, (size_t)clip_markers * 3, &t) == TETRIG_OK, "clip frame 0");
  CHECK(tetrig_rig_process_frame(rig, xyz, (size_t)clip_markers, t, 3, 0, sentinel, n - 1, NULL, 0, NULL) == TETRIG_ERROR_BUFFER_SIZE,
        "a short buffer");
  CHECK(sentinel[0] == -1.0f && sentinel[n - 2] == -1.0f, "a refused frame wrote");
  CHECK(tetrig_rig_process_frame(rig, xyz, (size_t)clip_markers - 1, t, 3, 0, x, n, NULL, 0, NULL) == TETRIG_ERROR_NOT_BOUND,
        "a frame of another marker count");

  /* The clip's first frames, 3 iterations each, no time limit (as `tetrig export --iterations 3`). */
  {
    float* first_markers = (float*)malloc(sizeof(float) * (size_t)clip_markers * 3);
    for (f = 0; f < frames; ++f) {
      CHECK(tetrig_clip_frame(clip, f, xyz, (size_t)clip_markers * 3, &t) == TETRIG_OK, "clip frame %ld", f);
      CHECK(t == f * (int64_t)8333333, "frame %ld time %lld: the clip's time line is frame * round(1e9 / 120 Hz)", f, (long long)t);
      if (f == 0) memcpy(first_markers, xyz, sizeof(float) * (size_t)clip_markers * 3);
      if (tetrig_rig_process_frame(rig, xyz, (size_t)clip_markers, t, 3, 0, x, n, NULL, 0, &stats) != TETRIG_OK) {
        CHECK(0, "frame %ld", f);
        break;
      }
      CHECK(stats.frames == (uint64_t)f + 1, "frame counter %llu", (unsigned long long)stats.frames);
      CHECK(stats.iterations == 3 && (stats.flags & TETRIG_FRAME_POSE_HELD) == 0, "frame %ld: %d iterations, flags %x", f,
            (int)stats.iterations, (unsigned)stats.flags);
      CHECK(stats.measured_markers == rig_markers && stats.occluded_markers == 0, "frame %ld: %d measured, %d occluded", f,
            (int)stats.measured_markers, (int)stats.occluded_markers);
      if (!allFinite(x, n)) {
        CHECK(0, "frame %ld: a non-finite position", f);
        break;
      }
      if (f == 0) memcpy(first, x, sizeof(float) * n);
    }
    marker_move = maxMove(first_markers, xyz, (size_t)clip_markers) * 1e-3; /* mm -> m */
    free(first_markers);
  }
  /* The mesh moved with the markers: the clip's markers move by at least 10 cm over these frames
   * (a check of the data), and the skin by at least half of what the markers did. */
  mesh_move = maxMove(first, x, (size_t)vertices);
  printf("markers moved up to %.3f m, the mesh up to %.3f m over %ld frames\n", marker_move, mesh_move, frames);
  CHECK(marker_move > 0.1, "the clip's markers moved %.3f m only: choose more frames", marker_move);
  CHECK(mesh_move > 0.5 * marker_move && mesh_move < 2.0 * marker_move, "the mesh moved %.3f m, the markers %.3f m", mesh_move, marker_move);
  CHECK(maxMove(first, rest, (size_t)vertices) < 0.2, "the first frame is near the rest pose (the rig was built from it)");
  if (out_path != NULL) {
    FILE* out = fopen(out_path, "wb");
    CHECK(out != NULL && fwrite(x, sizeof(float), n, out) == n, "writing %s", out_path);
    if (out != NULL) fclose(out);
  }

  /* An occluded marker (NaN) is predicted; the output stays finite. */
  xyz[0] = (float)NAN;
  CHECK(tetrig_rig_process_frame(rig, xyz, (size_t)clip_markers, t + 8333333, 3, 0, x, n, NULL, 0, &stats) == TETRIG_OK, "occluded frame");
  CHECK(stats.occluded_markers == 1 && (stats.flags & TETRIG_FRAME_MARKERS_PREDICTED) != 0, "occluded %d, flags %x",
        (int)stats.occluded_markers, (unsigned)stats.flags);
  CHECK(allFinite(x, n), "finite with an occluded marker");
  CHECK(tetrig_rig_frame_stats(rig, &stats) == TETRIG_OK && stats.frames == (uint64_t)frames + 1, "stats");

  free(labels);
  free(triangles);
  free(xyz);
  free(x);
  free(first);
  free(rest);
  free(sentinel);
  tetrig_clip_close(clip);
  tetrig_rig_close(rig);
  if (failures > 0) {
    printf("%d checks FAILED\n", failures);
    return 1;
  }
  printf("passed\n");
  return 0;
}
