/* An outside C99 program on the installed C API (tetrig.h, libtetrig): the clip's first FRAMES frames
 * through the rig, 3 iterations each; writes the last frame's positions (raw floats) to OUT.
 * usage: consumer_c RIG CLIP FRAMES OUT */
#include <tetrig.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int fail(const char* what) {
  fprintf(stderr, "consumer_c: %s: %s\n", what, tetrig_last_error());
  return 1;
}

int main(int argc, char** argv) {
  tetrig_rig* rig;
  tetrig_clip* clip;
  const char** labels;
  float *xyz, *x;
  int32_t markers, i;
  size_t n;
  long frames, f;
  int64_t t = 0;
  FILE* out;
  if (argc != 5) {
    fprintf(stderr, "usage: consumer_c RIG CLIP FRAMES OUT\n");
    return 2;
  }
  if (strcmp(tetrig_version(), TETRIG_VERSION_STRING) != 0) {
    fprintf(stderr, "consumer_c: library %s, header %s\n", tetrig_version(), TETRIG_VERSION_STRING);
    return 1;
  }
  frames = strtol(argv[3], NULL, 10);
  rig = tetrig_rig_open(argv[1], NULL);
  if (rig == NULL) return fail("open the rig");
  clip = tetrig_clip_open(argv[2]);
  if (clip == NULL) return fail("open the clip");
  markers = tetrig_clip_marker_count(clip);
  labels = (const char**)malloc(sizeof(const char*) * (size_t)markers);
  for (i = 0; i < markers; ++i) labels[i] = tetrig_clip_marker_label(clip, i);
  if (tetrig_rig_bind_labels(rig, labels, (size_t)markers) <= 0) return fail("bind");
  n = (size_t)tetrig_rig_vertex_count(rig) * 3;
  xyz = (float*)malloc(sizeof(float) * (size_t)markers * 3);
  x = (float*)malloc(sizeof(float) * n);
  for (f = 0; f < frames; ++f) {
    if (tetrig_clip_frame(clip, f, xyz, (size_t)markers * 3, &t) != TETRIG_OK) return fail("clip frame");
    if (tetrig_rig_process_frame(rig, xyz, (size_t)markers, t, 3, 0, x, n, NULL, 0, NULL) != TETRIG_OK) return fail("frame");
  }
  out = fopen(argv[4], "wb");
  if (out == NULL || fwrite(x, sizeof(float), n, out) != n) return fail("write");
  fclose(out);
  printf("consumer_c: tetrig %s, %ld frames, %zu vertices\n", tetrig_version(), frames, n / 3);
  free(labels);
  free(xyz);
  free(x);
  tetrig_clip_close(clip);
  tetrig_rig_close(rig);
  return 0;
}
