/* tetrig-shm-cat: a C99 consumer of the tetrig shared-memory segment, using only tetrig_shm.h
 * and libc (docs/shm.md, "tetrig-shm-cat"). Waits for the segment, prints one line per new frame
 * (frame id, source frame, iterations, receive->publish and publish->seen latencies), tells a
 * dead producer from a slow one and a restarted producer from the old one, and can write latency
 * percentiles as JSON (--json: receive->published, published->seen, receive->seen) and every frame's positions as raw binary (--dump).
 * --markers adds, under each frame line, one line per marker of a layout 1.1 segment (label, state,
 * position in rig units), read with the frame's mesh in one read.
 *
 *   tetrig-shm-cat NAME [--frames N] [--timeout-ms T] [--json FILE] [--dump FILE]
 *                       [--follow] [--quiet] [--markers] [--poll-us U] [--stale-ms S] [--owner UID]
 *
 * The segment must belong to this process's effective uid (--owner UID accepts that user's
 * segment instead) and must not be writable by group or others.
 *
 * Exit status: 0 after N frames or when the producer stopped cleanly; 1 usage or file error;
 * 2 timeout (no segment / no new frame for T ms); 3 producer died (without --follow);
 * 4 segment unusable (not a tetrig segment, unknown major version, inconsistent sizes, another
 * owner, writable by group or others).
 *
 * --dump format (little-endian): the 8 bytes "TSHMDMP1", then one record per frame seen:
 * uint64 instance_id, uint64 frame_id, uint32 vertex_count, uint32 reserved (0),
 * vertex_count x 3 float32 positions, exactly as read from the slot. */
#include "tetrig_shm.h" /* first: it sets _POSIX_C_SOURCE for strict C99 */

#include <inttypes.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define EXIT_OK 0
#define EXIT_USAGE 1
#define EXIT_TIMEOUT 2
#define EXIT_DEAD 3
#define EXIT_UNUSABLE 4

typedef struct Options {
  const char* name;
  uint64_t frames;    /* 0: until the producer stops */
  int64_t timeout_ms; /* without progress */
  const char* json_path;
  const char* dump_path;
  int follow; /* keep waiting for a new producer after a crash */
  int quiet;  /* no per-frame lines */
  int markers; /* a line per marker under each frame line (layout 1.1) */
  long poll_us;
  int64_t stale_ms;
  uid_t owner; /* the uid the segment must belong to (default: geteuid()) */
} Options;

typedef struct Samples {
  double* values;
  size_t count;
  size_t capacity;
} Samples;

static int samplesPush(Samples* s, double v) {
  if (s->count == s->capacity) {
    const size_t cap = s->capacity == 0 ? 1024 : s->capacity * 2;
    double* grown = (double*)realloc(s->values, cap * sizeof *grown);
    if (grown == NULL) return 0;
    s->values = grown;
    s->capacity = cap;
  }
  s->values[s->count++] = v;
  return 1;
}

static int compareDoubles(const void* a, const void* b) {
  const double x = *(const double*)a;
  const double y = *(const double*)b;
  return (x > y) - (x < y);
}

/* Nearest-rank percentile of sorted values (p in (0, 1]). */
static double percentile(const Samples* s, double p) {
  size_t rank = (size_t)(p * (double)s->count + 0.999999);
  if (rank < 1) rank = 1;
  if (rank > s->count) rank = s->count;
  return s->values[rank - 1];
}

static void writeStats(FILE* f, const char* key, Samples* s, int last) {
  if (s->count == 0) {
    fprintf(f, "    \"%s\": {\"count\": 0, \"p50\": null, \"p99\": null, \"max\": null}%s\n", key, last ? "" : ",");
    return;
  }
  qsort(s->values, s->count, sizeof *s->values, compareDoubles);
  fprintf(f, "    \"%s\": {\"count\": %lu, \"p50\": %.3f, \"p99\": %.3f, \"max\": %.3f}%s\n", key,
          (unsigned long)s->count, percentile(s, 0.50), percentile(s, 0.99), s->values[s->count - 1], last ? "" : ",");
}

static void sleepMicroseconds(long us) {
  if (us <= 0) {
    sched_yield();
  } else {
    struct timespec ts;
    ts.tv_sec = us / 1000000L;
    ts.tv_nsec = (us % 1000000L) * 1000L;
    nanosleep(&ts, NULL);
  }
}

static int parseInteger(const char* text, long long min, long long* out) {
  char* end = NULL;
  long long v;
  errno = 0;
  v = strtoll(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || v < min) return 0;
  *out = v;
  return 1;
}

static void usage(void) {
  fprintf(stderr,
          "usage: tetrig-shm-cat [NAME] [--frames N] [--timeout-ms T] [--json FILE] [--dump FILE]\n"
          "                      [--follow] [--quiet] [--markers] [--poll-us U] [--stale-ms S] [--owner UID]\n"
          "  NAME          segment name (default tetrig, tetrig run's; a leading '/' is added when missing)\n"
          "  --frames N    exit 0 after N new frames (default: until the producer stops)\n"
          "  --timeout-ms  give up (exit 2) after T ms without a segment or a new frame (default 5000)\n"
          "  --json FILE   write frames seen/missed and p50/p99/max latencies in microseconds\n"
          "  --dump FILE   write every frame seen: id and positions, raw little-endian (docs/shm.md)\n"
          "  --follow      after a crash, wait for a new producer instead of exiting 3\n"
          "  --quiet       no line per frame\n"
          "  --markers     under each frame line, each marker's label, state and position (layout 1.1)\n"
          "  --poll-us U   sleep between polls (default 100; 0 = yield)\n"
          "  --stale-ms S  heartbeat age that counts as stale (default 1000)\n"
          "  --owner UID   accept a segment of this user (default: only our own effective uid's)\n");
}

static int parseOptions(int argc, char** argv, Options* o, char* name_buf, size_t name_cap) {
  int i;
  long long v;
  memset(o, 0, sizeof *o);
  o->timeout_ms = 5000;
  o->poll_us = 100;
  o->stale_ms = 1000;
  o->owner = geteuid();
  for (i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const int has_value = i + 1 < argc;
    if (strcmp(a, "--frames") == 0 && has_value && parseInteger(argv[i + 1], 0, &v)) {
      o->frames = (uint64_t)v;
      ++i;
    } else if (strcmp(a, "--timeout-ms") == 0 && has_value && parseInteger(argv[i + 1], 0, &v)) {
      o->timeout_ms = (int64_t)v;
      ++i;
    } else if (strcmp(a, "--poll-us") == 0 && has_value && parseInteger(argv[i + 1], 0, &v) && v <= 1000000) {
      o->poll_us = (long)v;
      ++i;
    } else if (strcmp(a, "--stale-ms") == 0 && has_value && parseInteger(argv[i + 1], 1, &v)) {
      o->stale_ms = (int64_t)v;
      ++i;
    } else if (strcmp(a, "--owner") == 0 && has_value && parseInteger(argv[i + 1], 0, &v) &&
               (long long)(uid_t)v == v && (uid_t)v != (uid_t)-1) {
      o->owner = (uid_t)v;
      ++i;
    } else if (strcmp(a, "--json") == 0 && has_value) {
      o->json_path = argv[++i];
    } else if (strcmp(a, "--dump") == 0 && has_value) {
      o->dump_path = argv[++i];
    } else if (strcmp(a, "--follow") == 0) {
      o->follow = 1;
    } else if (strcmp(a, "--quiet") == 0) {
      o->quiet = 1;
    } else if (strcmp(a, "--markers") == 0) {
      o->markers = 1;
    } else if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
      usage();
      exit(EXIT_OK);
    } else if (a[0] != '-' && o->name == NULL) {
      o->name = a;
    } else {
      fprintf(stderr, "tetrig-shm-cat: bad argument '%s'\n", a);
      return 0;
    }
  }
  if (o->name == NULL) o->name = "tetrig"; /* tetrig run's default --publish name */
  if (o->name[0] != '/') {
    if (strlen(o->name) + 2 > name_cap) {
      fprintf(stderr, "tetrig-shm-cat: segment name too long\n");
      return 0;
    }
    name_buf[0] = '/';
    memcpy(name_buf + 1, o->name, strlen(o->name) + 1);
    o->name = name_buf;
  }
  return 1;
}

static const char* stateName(uint32_t state) {
  switch (state) {
    case TETRIG_SHM_STATE_RUNNING: return "running";
    case TETRIG_SHM_STATE_STALE_SOURCE: return "stale source";
    case TETRIG_SHM_STATE_STOPPED: return "stopped";
    default: return "starting";
  }
}

typedef struct Run {
  Options opt;
  TetrigShmReader reader;
  int open;
  float* positions;
  size_t positions_len;
  int with_markers;        /* --markers and the segment has the marker block */
  float* marker_positions; /* marker_count x 3 */
  uint8_t* marker_states;  /* marker_count */
  size_t marker_len;       /* markers the buffers hold */
  uint64_t last_frame_id; /* of the current instance */
  uint64_t previous_instance;
  int32_t previous_pid;
  uint64_t frames_seen;
  uint64_t frames_missed;
  uint64_t instances;
  uint64_t retries; /* summed over instances */
  int warned_stale;
  int reported_death;
  Samples receive_to_publish;
  Samples publish_to_seen;
  Samples receive_to_seen;
  FILE* dump;
} Run;

static int64_t nowMs(void) { return tetrig_shm_now_ns() / INT64_C(1000000); }

/* Text from the segment (the rig's name, set from a rig file by whichever process made the
 * segment) printed with every control byte and every non-ASCII byte as \xNN, so that it cannot
 * send escape sequences to the terminal (C99 and libc only: no UTF-8 decoding here). */
static void writePrintable(FILE* f, const char* text) {
  const unsigned char* p;
  for (p = (const unsigned char*)text; *p != 0u; ++p) {
    if (*p < 0x20u || *p >= 0x7Fu) {
      fprintf(f, "\\x%02x", (unsigned)*p);
    } else {
      fputc(*p, f);
    }
  }
}

static void closeReader(Run* run) {
  if (run->open) {
    run->retries += run->reader.retries;
    tetrig_shm_close(&run->reader);
    run->open = 0;
  }
}

/* Returns EXIT_OK when opened, -1 to keep waiting, or an exit status. */
static int tryOpen(Run* run) {
  const int rc = tetrig_shm_open_as(&run->reader, run->opt.name, run->opt.owner);
  size_t need;
  char rig_name[256];
  if (rc == TETRIG_SHM_E_NOT_FOUND || rc == TETRIG_SHM_E_NOT_READY) return -1;
  if (rc == TETRIG_SHM_E_OWNER) {
    fprintf(stderr, "tetrig-shm-cat: cannot use segment %s: it belongs to uid %lu, not %lu (--owner %lu accepts it)\n",
            run->opt.name, (unsigned long)run->reader.owner_uid, (unsigned long)run->opt.owner,
            (unsigned long)run->reader.owner_uid);
    return EXIT_UNUSABLE;
  }
  if (rc == TETRIG_SHM_E_MODE) {
    fprintf(stderr, "tetrig-shm-cat: cannot use segment %s: mode %04lo lets group or others write it (rewrite or "
            "truncate it under its readers); the producer must not widen write permission\n",
            run->opt.name, (unsigned long)run->reader.mode);
    return EXIT_UNUSABLE;
  }
  if (rc != TETRIG_SHM_OK) {
    fprintf(stderr, "tetrig-shm-cat: cannot use segment %s: %s%s%s\n", run->opt.name, tetrig_shm_status_string(rc),
            rc == TETRIG_SHM_E_SYSTEM || rc == TETRIG_SHM_E_ACCESS ? ": " : "",
            rc == TETRIG_SHM_E_SYSTEM || rc == TETRIG_SHM_E_ACCESS ? strerror(run->reader.error) : "");
    return rc == TETRIG_SHM_E_ACCESS || rc == TETRIG_SHM_E_SYSTEM || rc == TETRIG_SHM_E_ARGUMENT ? EXIT_USAGE : EXIT_UNUSABLE;
  }
  if (run->instances > 0 && run->reader.instance_id == run->previous_instance) {
    /* the same (dead or stopped) segment again: not a new producer yet */
    tetrig_shm_close(&run->reader);
    return -1;
  }
  run->open = 1;
  need = (size_t)tetrig_shm_vertex_count(&run->reader) * 3u;
  if (need > run->positions_len) {
    float* grown = (float*)realloc(run->positions, need * sizeof *grown);
    if (grown == NULL) {
      fprintf(stderr, "tetrig-shm-cat: out of memory\n");
      return EXIT_USAGE;
    }
    run->positions = grown;
    run->positions_len = need;
  }
  run->with_markers = run->opt.markers && tetrig_shm_has_marker_positions(&run->reader);
  if (run->with_markers && tetrig_shm_marker_count(&run->reader) > run->marker_len) {
    const size_t m = tetrig_shm_marker_count(&run->reader);
    float* grown = (float*)realloc(run->marker_positions, m * 3u * sizeof *grown);
    uint8_t* states;
    if (grown != NULL) run->marker_positions = grown;
    states = grown == NULL ? NULL : (uint8_t*)realloc(run->marker_states, m);
    if (states == NULL) {
      fprintf(stderr, "tetrig-shm-cat: out of memory\n");
      return EXIT_USAGE;
    }
    run->marker_states = states;
    run->marker_len = m;
  }
  if (run->instances > 0) {
    fprintf(stderr, "tetrig-shm-cat: producer restarted: instance %016" PRIx64 " (pid %ld) -> %016" PRIx64 " (pid %ld)\n",
            run->previous_instance, (long)run->previous_pid, run->reader.instance_id, (long)run->reader.producer_pid);
  }
  fprintf(stderr, "tetrig-shm-cat: %s: rig '", run->opt.name);
  tetrig_shm_copy_rig_name(&run->reader, rig_name, sizeof rig_name);
  writePrintable(stderr, rig_name);
  fprintf(stderr, "', %lu vertices, %lu triangles, %lu slots%s, instance %016" PRIx64 ", pid %ld, state %s\n",
          (unsigned long)tetrig_shm_vertex_count(&run->reader),
          (unsigned long)tetrig_shm_triangle_count(&run->reader), (unsigned long)tetrig_shm_slot_count(&run->reader),
          tetrig_shm_has_normals(&run->reader) ? ", normals" : "", run->reader.instance_id,
          (long)run->reader.producer_pid, stateName(tetrig_shm_state(&run->reader)));
  if (run->opt.markers && !run->with_markers) {
    fprintf(stderr, "tetrig-shm-cat: %s has no marker positions (layout %u.%u, %lu marker labels): no marker lines\n",
            run->opt.name, (unsigned)run->reader.header_copy.version_major, (unsigned)run->reader.header_copy.version_minor,
            (unsigned long)tetrig_shm_marker_count(&run->reader));
  }
  run->instances += 1;
  run->previous_instance = run->reader.instance_id;
  run->previous_pid = run->reader.producer_pid;
  run->last_frame_id = 0;
  run->warned_stale = 0;
  run->reported_death = 0;
  return EXIT_OK;
}

static int writeDump(Run* run, const TetrigShmFrameInfo* info) {
  unsigned char head[24];
  const uint32_t vertices = tetrig_shm_vertex_count(&run->reader);
  const uint32_t reserved = 0;
  memcpy(head, &run->reader.instance_id, 8);
  memcpy(head + 8, &info->frame_id, 8);
  memcpy(head + 16, &vertices, 4);
  memcpy(head + 20, &reserved, 4);
  return fwrite(head, 1, sizeof head, run->dump) == sizeof head &&
         fwrite(run->positions, sizeof(float), (size_t)vertices * 3u, run->dump) == (size_t)vertices * 3u;
}

/* Handles the newest frame; returns 1 when a new frame was taken, 0 when none, or -(status). */
static int takeFrame(Run* run) {
  TetrigShmFrameInfo info;
  int64_t seen_ns, recv_pub, pub_seen, recv_seen;
  const int rc = run->with_markers
                     ? tetrig_shm_read_latest_markers(&run->reader, run->positions, run->positions_len, NULL, 0,
                                                      run->marker_positions, run->marker_len * 3u, run->marker_states,
                                                      run->marker_len, &info)
                     : tetrig_shm_read_latest(&run->reader, run->positions, run->positions_len, NULL, 0, &info);
  if (rc != TETRIG_SHM_OK || info.frame_id <= run->last_frame_id) return 0; /* BUSY: next poll retries */
  seen_ns = tetrig_shm_now_ns();
  if (run->last_frame_id != 0) run->frames_missed += info.frame_id - run->last_frame_id - 1u;
  run->last_frame_id = info.frame_id;
  run->frames_seen += 1;
  recv_pub = tetrig_shm_receive_to_publish_ns(&info);
  pub_seen = tetrig_shm_publish_age_ns(&info, seen_ns);
  recv_seen = tetrig_shm_interval_ns(info.receive_ns, seen_ns);
  if ((recv_pub >= 0 && !samplesPush(&run->receive_to_publish, (double)recv_pub * 1e-3)) ||
      (pub_seen >= 0 && !samplesPush(&run->publish_to_seen, (double)pub_seen * 1e-3)) ||
      (recv_seen >= 0 && !samplesPush(&run->receive_to_seen, (double)recv_seen * 1e-3))) {
    fprintf(stderr, "tetrig-shm-cat: out of memory\n");
    return -EXIT_USAGE;
  }
  if (!run->opt.quiet) {
    char recv_text[32];
    if (recv_pub >= 0) {
      snprintf(recv_text, sizeof recv_text, "%.1f", (double)recv_pub * 1e-3);
    } else {
      snprintf(recv_text, sizeof recv_text, "-");
    }
    printf("frame %" PRIu64 " source %" PRIu64 " iter %ld recv->pub %s us pub->seen %.1f us flags 0x%lx occluded %u\n",
           info.frame_id, info.source_frame, (long)info.iterations, recv_text, (double)pub_seen * 1e-3,
           (unsigned long)info.flags, (unsigned)info.occluded_markers);
    if (run->with_markers) {
      static const char* const kStateNames[4] = {"unknown", "measured", "predicted", "blended"};
      uint32_t k;
      for (k = 0; k < tetrig_shm_marker_count(&run->reader); ++k) {
        const float* xyz = run->marker_positions + 3u * k;
        const uint8_t st = run->marker_states[k];
        char label[256];
        tetrig_shm_copy_marker_label(&run->reader, k, label, sizeof label); /* "" if the block was rewritten */
        fputs("  marker ", stdout);
        writePrintable(stdout, label);
        printf(" %s %.9g %.9g %.9g\n", st < 4u ? kStateNames[st] : "unknown", (double)xyz[0], (double)xyz[1], (double)xyz[2]);
      }
    }
    fflush(stdout);
  }
  if (run->dump != NULL && !writeDump(run, &info)) {
    fprintf(stderr, "tetrig-shm-cat: cannot write %s: %s\n", run->opt.dump_path, strerror(errno));
    return -EXIT_USAGE;
  }
  return 1;
}

/* No new frame: checks the producer. Returns -1 to keep going, or an exit status. */
static int checkProducer(Run* run) {
  const int status = tetrig_shm_producer_status(&run->reader, run->opt.stale_ms * INT64_C(1000000));
  const int64_t age_ms = tetrig_shm_heartbeat_age_ns(&run->reader, tetrig_shm_now_ns()) / INT64_C(1000000);
  if (status == TETRIG_SHM_PRODUCER_ALIVE) {
    if (run->warned_stale) fprintf(stderr, "tetrig-shm-cat: producer pid %ld responds again\n", (long)run->reader.producer_pid);
    run->warned_stale = 0;
    return -1;
  }
  if (status == TETRIG_SHM_PRODUCER_STALE) {
    if (!run->warned_stale) {
      fprintf(stderr, "tetrig-shm-cat: producer pid %ld is alive but its heartbeat is %ld ms old (hung, paused or starved)\n",
              (long)run->reader.producer_pid, (long)age_ms);
    }
    run->warned_stale = 1;
    return -1;
  }
  /* stopped or dead: was the name taken over by a new producer? */
  if (tetrig_shm_name_status(&run->reader) == TETRIG_SHM_NAME_REPLACED) {
    closeReader(run); /* the main loop opens the new one and reports the restart */
    return -1;
  }
  if (status == TETRIG_SHM_PRODUCER_STOPPED) {
    if (run->opt.follow) {
      if (!run->reported_death) fprintf(stderr, "tetrig-shm-cat: producer pid %ld stopped; waiting for a new one (--follow)\n",
                                        (long)run->reader.producer_pid);
      run->reported_death = 1;
      return -1;
    }
    fprintf(stderr, "tetrig-shm-cat: producer pid %ld stopped cleanly\n", (long)run->reader.producer_pid);
    return EXIT_OK;
  }
  if (run->opt.follow) {
    if (!run->reported_death) {
      fprintf(stderr, "tetrig-shm-cat: producer pid %ld died (heartbeat %ld ms old); waiting for a new one (--follow)\n",
              (long)run->reader.producer_pid, (long)age_ms);
    }
    run->reported_death = 1;
    return -1;
  }
  fprintf(stderr, "tetrig-shm-cat: producer pid %ld died without stopping (heartbeat %ld ms old)\n",
          (long)run->reader.producer_pid, (long)age_ms);
  return EXIT_DEAD;
}

/* JSON string body: quotes, backslashes and control characters escaped. */
static void writeJsonString(FILE* f, const char* text) {
  const unsigned char* p;
  for (p = (const unsigned char*)text; *p != 0u; ++p) {
    if (*p == '"' || *p == '\\') {
      fprintf(f, "\\%c", *p);
    } else if (*p < 0x20u) {
      fprintf(f, "\\u%04x", (unsigned)*p);
    } else {
      fputc(*p, f);
    }
  }
}

static int writeJson(Run* run) {
  FILE* f = fopen(run->opt.json_path, "w");
  if (f == NULL) {
    fprintf(stderr, "tetrig-shm-cat: cannot write %s: %s\n", run->opt.json_path, strerror(errno));
    return 0;
  }
  fprintf(f, "{\n  \"name\": \"");
  writeJsonString(f, run->opt.name);
  fprintf(f, "\",\n");
  fprintf(f, "  \"frames_seen\": %" PRIu64 ",\n  \"frames_missed\": %" PRIu64 ",\n", run->frames_seen, run->frames_missed);
  fprintf(f, "  \"instances\": %" PRIu64 ",\n  \"reader_retries\": %" PRIu64 ",\n", run->instances, run->retries);
  fprintf(f, "  \"latency_us\": {\n");
  writeStats(f, "receive_to_published", &run->receive_to_publish, 0);
  writeStats(f, "published_to_seen", &run->publish_to_seen, 0);
  writeStats(f, "receive_to_seen", &run->receive_to_seen, 1);
  fprintf(f, "  }\n}\n");
  return fclose(f) == 0;
}

static int loop(Run* run) {
  int64_t deadline = nowMs() + run->opt.timeout_ms;
  int64_t next_check = 0;
  for (;;) {
    int64_t now;
    if (!run->open) {
      const int rc = tryOpen(run);
      if (rc >= 0) {
        if (rc != EXIT_OK) return rc;
        deadline = nowMs() + run->opt.timeout_ms;
        continue;
      }
    } else {
      const int got = takeFrame(run);
      if (got < 0) return -got;
      if (got > 0) {
        deadline = nowMs() + run->opt.timeout_ms;
        if (run->opt.frames != 0 && run->frames_seen >= run->opt.frames) return EXIT_OK;
        continue;
      }
      now = nowMs();
      if (now >= next_check) {
        const int rc = checkProducer(run);
        if (rc >= 0) return rc;
        next_check = now + 20;
      }
    }
    now = nowMs();
    if (now >= deadline) {
      if (!run->open) {
        fprintf(stderr, "tetrig-shm-cat: timed out after %ld ms waiting for %s%s\n", (long)run->opt.timeout_ms,
                run->instances > 0 ? "a new producer of " : "segment ", run->opt.name);
      } else {
        fprintf(stderr, "tetrig-shm-cat: timed out: no new frame on %s for %ld ms (producer pid %ld, state %s)\n",
                run->opt.name, (long)run->opt.timeout_ms, (long)run->reader.producer_pid,
                stateName(tetrig_shm_state(&run->reader)));
      }
      return EXIT_TIMEOUT;
    }
    sleepMicroseconds(run->opt.poll_us);
  }
}

int main(int argc, char** argv) {
  static Run run; /* zeroed */
  char name_buf[TETRIG_SHM_NAME_MAX + 2];
  int status;
  if (!parseOptions(argc, argv, &run.opt, name_buf, sizeof name_buf)) {
    usage();
    return EXIT_USAGE;
  }
  if (run.opt.dump_path != NULL) {
    run.dump = fopen(run.opt.dump_path, "wb");
    if (run.dump == NULL || fwrite("TSHMDMP1", 1, 8, run.dump) != 8) {
      fprintf(stderr, "tetrig-shm-cat: cannot write %s: %s\n", run.opt.dump_path, strerror(errno));
      return EXIT_USAGE;
    }
  }
  status = loop(&run);
  closeReader(&run);
  if (run.dump != NULL && fclose(run.dump) != 0) {
    fprintf(stderr, "tetrig-shm-cat: cannot write %s: %s\n", run.opt.dump_path, strerror(errno));
    if (status == EXIT_OK) status = EXIT_USAGE;
  }
  if (run.opt.json_path != NULL && !writeJson(&run) && status == EXIT_OK) status = EXIT_USAGE;
  fprintf(stderr, "tetrig-shm-cat: %" PRIu64 " frames seen, %" PRIu64 " missed, %" PRIu64 " producer instance(s)\n",
          run.frames_seen, run.frames_missed, run.instances);
  free(run.positions);
  free(run.marker_positions);
  free(run.marker_states);
  free(run.receive_to_publish.values);
  free(run.publish_to_seen.values);
  free(run.receive_to_seen.values);
  return status;
}
