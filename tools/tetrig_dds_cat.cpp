// tetrig-dds-cat: a subscriber of one performer's DDS topics (docs/dds.md, "tetrig-dds-cat"), the
// DDS counterpart of tetrig-shm-cat: frame lines, the static data it got, refused samples, the
// publisher's liveliness, latency JSON and raw dumps in tetrig-shm-cat's dump format.
#include "tetrig/dds/frame_subscriber.hpp"

#include <algorithm>
#include <cerrno>
#include <cinttypes>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <string>
#include <vector>

namespace {

volatile std::sig_atomic_t g_stop = 0;
void onSignal(int) { g_stop = 1; }

const char* kUsage =
    "usage: tetrig-dds-cat NAME [--frames N] [--timeout-ms T] [--latency-json FILE] [--dump FILE] [--follow] [--quiet]\n"
    "                      [--domain D]\n"
    "  NAME: the --publish name of `tetrig run --dds` (topics tetrig/NAME/frame and tetrig/NAME/static; '-' and '.' read as '_')\n";

struct Args {
  std::string name;
  std::uint64_t frames = 0;
  long long timeout_ms = 5000;
  std::string latency_json, dump;
  bool follow = false, quiet = false;
  int domain = -1;
};

bool parseNumber(const char* text, long long min, long long max, long long& out) {
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || v < min || v > max) return false;
  out = v;
  return true;
}

// Nearest-rank percentile of sorted microseconds, or -1 without samples.
double percentile(const std::vector<double>& sorted, double p) {
  if (sorted.empty()) return -1;
  std::size_t rank = static_cast<std::size_t>(p * static_cast<double>(sorted.size()) + 0.999999);
  rank = std::clamp<std::size_t>(rank, 1, sorted.size());
  return sorted[rank - 1];
}

std::string statsJson(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  if (v.empty()) return "{\"count\": 0, \"p50\": null, \"p99\": null, \"max\": null}";
  char buf[160];
  std::snprintf(buf, sizeof buf, "{\"count\": %zu, \"p50\": %.1f, \"p99\": %.1f, \"max\": %.1f}", v.size(), percentile(v, 0.5),
                percentile(v, 0.99), v.back());
  return buf;
}

// JSON string of text that may hold any bytes (rig names come from files): control and non-ASCII bytes escaped.
std::string jsonString(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u >= 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", u);
      out += buf;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

// Printable form of text from the wire: control bytes and bytes >= 0x7f as \xNN, cut at 64.
std::string printable(const std::string& s) {
  std::string out;
  for (std::size_t i = 0; i < s.size() && i < 64; ++i) {
    const auto u = static_cast<unsigned char>(s[i]);
    if (u < 0x20 || u >= 0x7f || s[i] == '\\') {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", u);
      out += buf;
    } else {
      out += s[i];
    }
  }
  return s.size() > 64 ? out + "..." : out;
}

const char* stateName(std::uint8_t s) {
  switch (s) {
    case 1: return "running";
    case 2: return "stale-source";
    case 3: return "stopped";
    default: return "unknown";
  }
}

// Reads the command line into a; returns -1 to go on, else the exit status (--help: 0, a mistake: 1).
int parseArgs(int argc, char** argv, Args& a) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](const char* what) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "tetrig-dds-cat: %s needs a value\n%s", what, kUsage);
        std::exit(1);
      }
      return argv[++i];
    };
    long long n = 0;
    if (arg == "--frames") {
      if (!parseNumber(value("--frames"), 1, INT64_MAX, n)) return std::fprintf(stderr, "tetrig-dds-cat: --frames needs a number >= 1\n"), 1;
      a.frames = static_cast<std::uint64_t>(n);
    } else if (arg == "--timeout-ms") {
      if (!parseNumber(value("--timeout-ms"), 1, 86'400'000, a.timeout_ms))
        return std::fprintf(stderr, "tetrig-dds-cat: --timeout-ms needs a number of milliseconds >= 1\n"), 1;
    } else if (arg == "--domain") {
      if (!parseNumber(value("--domain"), 0, 232, n)) return std::fprintf(stderr, "tetrig-dds-cat: --domain needs a number 0..232\n"), 1;
      a.domain = static_cast<int>(n);
    } else if (arg == "--latency-json") {
      a.latency_json = value("--latency-json");
    } else if (arg == "--dump") {
      a.dump = value("--dump");
    } else if (arg == "--follow") {
      a.follow = true;
    } else if (arg == "--quiet" || arg == "-q") {
      a.quiet = true;
    } else if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (!arg.empty() && arg[0] == '-') {
      std::fprintf(stderr, "tetrig-dds-cat: unknown option '%s'\n%s", printable(arg).c_str(), kUsage);
      return 1;
    } else if (a.name.empty()) {
      a.name = arg;
    } else {
      std::fprintf(stderr, "tetrig-dds-cat: one NAME only ('%s' and '%s')\n", printable(a.name).c_str(), printable(arg).c_str());
      return 1;
    }
  }
  if (a.name.empty()) {
    std::fprintf(stderr, "tetrig-dds-cat: no NAME given\n%s", kUsage);
    return 1;
  }
  return -1;
}

// What the subscriber saw: the frame checker, the counts and latencies, the frames held for their
// static data; and whether and how it is done.
struct Subscription {
  Subscription(const Args& args, std::FILE* dump_file, long long lease) : a(args), dump(dump_file), lease_ms(lease) {}

  const Args& a;
  std::FILE* dump;
  const long long lease_ms;  // the publishers' liveliness lease
  tetrig::dds::FrameChecker checker;
  std::vector<double> receive_to_seen, published_to_seen, written_to_seen;
  std::uint64_t seen = 0, missed = 0, refused = 0, static_refused = 0, before_static = 0, instances = 0, lost = 0;
  std::uint64_t last_instance = 0, last_id = 0;
  std::size_t bytes_per_frame = 0;
  std::string rig_name;
  std::uint32_t vertex_count = 0;
  std::int64_t last_activity = tetrig::dds::monotonicNs();
  const std::int64_t start = last_activity;
  int exit_code = 0;
  bool done = false;
  // Frames that came before their instance's static data (the two topics are not ordered with
  // each other): held, at most kPending, and checked once it comes.
  static constexpr std::size_t kPending = 16;
  std::deque<tetrig::dds::ReceivedFrame> pending;

  // Checks, counts, prints and dumps one frame; true when --frames is reached.
  bool onFrame(const tetrig::dds::ReceivedFrame& f, std::int64_t now) {
    std::string why;
    const auto verdict = checker.checkFrame(f, why);
    if (verdict == tetrig::dds::FrameChecker::Verdict::kWaitingForStatic) {
      if (pending.size() == kPending) {
        pending.pop_front();
        ++before_static;
      }
      pending.push_back(f);
      return false;
    }
    if (verdict == tetrig::dds::FrameChecker::Verdict::kRefused) {
      ++refused;
      std::fprintf(stderr, "tetrig-dds-cat: %s (%" PRIu64 " refused so far)\n", why.c_str(), refused);
      return false;
    }
    last_activity = now;
    if (f.instance_id != last_instance) {
      if (last_instance != 0)
        std::fprintf(stderr, "tetrig-dds-cat: publisher restarted: instance %016" PRIx64 " -> %016" PRIx64 "\n", last_instance, f.instance_id);
      ++instances;
      last_instance = f.instance_id;
    } else if (f.frame_id > last_id + 1) {
      missed += f.frame_id - last_id - 1;
    }
    last_id = f.frame_id;
    ++seen;
    bytes_per_frame = f.payloadBytes();
    const double rs = f.receive_ns > 0 && f.seen_ns >= f.receive_ns ? static_cast<double>(f.seen_ns - f.receive_ns) * 1e-3 : -1;
    const double ps = f.publish_ns > 0 && f.seen_ns >= f.publish_ns ? static_cast<double>(f.seen_ns - f.publish_ns) * 1e-3 : -1;
    const double ws = f.write_ns > 0 && f.seen_ns >= f.write_ns ? static_cast<double>(f.seen_ns - f.write_ns) * 1e-3 : -1;
    if (rs >= 0) receive_to_seen.push_back(rs);
    if (ps >= 0) published_to_seen.push_back(ps);
    if (ws >= 0) written_to_seen.push_back(ws);
    if (!a.quiet) {
      char recv[32] = "-";
      if (rs >= 0) std::snprintf(recv, sizeof recv, "%.1f us", rs);
      std::printf("frame %" PRIu64 " source %" PRIu64 " iter %d recv->seen %s pub->seen %.1f us bytes %zu flags 0x%x state %s\n", f.frame_id,
                  f.source_frame, f.iterations, recv, ps, bytes_per_frame, f.flags, stateName(f.producer_state));
    }
    if (dump != nullptr) {
      const std::uint32_t v = static_cast<std::uint32_t>(f.positions.size() / 3), zero = 0;
      std::fwrite(&f.instance_id, 8, 1, dump);
      std::fwrite(&f.frame_id, 8, 1, dump);
      std::fwrite(&v, 4, 1, dump);
      std::fwrite(&zero, 4, 1, dump);
      std::fwrite(f.positions.data(), sizeof(float), f.positions.size(), dump);
    }
    return a.frames > 0 && seen >= a.frames;
  }

  // Static data: accepted (its frames held so far are checked now) or refused.
  void onStatic(const tetrig::dds::SubscriberEvent& e, std::int64_t now) {
    std::string why;
    if (checker.acceptStatic(e.static_data, why)) {
      rig_name = e.static_data.rig_name;
      vertex_count = e.static_data.vertex_count;
      std::fprintf(stderr, "tetrig-dds-cat: static data: rig '%s', %u vertices, %zu triangles, %zu markers%s (instance %016" PRIx64 ")\n",
                   printable(rig_name).c_str(), vertex_count, e.static_data.triangles.size() / 3, e.static_data.marker_labels.size(),
                   e.static_data.has_normals ? ", normals" : "", e.static_data.instance_id);
      // The frames held for this instance, in the order they came.
      std::deque<tetrig::dds::ReceivedFrame> held;
      held.swap(pending);
      for (const auto& f : held) {
        if (f.instance_id != e.static_data.instance_id) {
          pending.push_back(f);
        } else if (!(a.frames > 0 && seen >= a.frames) && onFrame(f, now)) {
          done = true;
        }
      }
    } else {
      ++static_refused;
      std::fprintf(stderr, "tetrig-dds-cat: %s\n", why.c_str());
    }
  }

  // One event: the publisher alive, lost or gone, static data, or a frame.
  void onEvent(const tetrig::dds::SubscriberEvent& e, std::int64_t now) {
    using K = tetrig::dds::SubscriberEvent;
    if (e.kind == K::kPublisherAlive) {
      last_activity = now;
      if (!a.quiet) std::fprintf(stderr, "tetrig-dds-cat: publisher alive (%d alive)\n", e.alive_count);
    } else if (e.kind == K::kPublisherLost) {
      ++lost;
      std::fprintf(stderr, "tetrig-dds-cat: publisher lost: no sign of it for the liveliness lease (%lld ms); last frame %.0f ms ago (%d alive)\n",
                   lease_ms, static_cast<double>(now - last_activity) * 1e-6, e.alive_count);
      if (!a.follow && e.alive_count == 0) {
        exit_code = 3;
        done = true;
      }
    } else if (e.kind == K::kPublisherLeft) {
      if (!a.quiet) std::fprintf(stderr, "tetrig-dds-cat: publisher left (a clean stop; %d alive)\n", e.alive_count);
      if (!a.follow && e.alive_count == 0) done = true;
    } else if (e.kind == K::kStatic) {
      onStatic(e, now);
    } else if (!(a.frames > 0 && seen >= a.frames) && onFrame(e.frame, now)) {
      done = true;  // frames of this batch after a liveliness event still count: the events come first
    }
  }

  // Waits up to 20 ms for events and handles them; a publisher silent for --timeout-ms ends the run.
  void poll(tetrig::dds::FrameSubscriber& sub, std::vector<tetrig::dds::SubscriberEvent>& events) {
    events.clear();
    sub.poll(20'000'000, events);
    const std::int64_t now = tetrig::dds::monotonicNs();
    for (const tetrig::dds::SubscriberEvent& e : events) {
      onEvent(e, now);
      if (a.frames > 0 && seen >= a.frames) break;
    }
    if (!done && now - last_activity > a.timeout_ms * 1'000'000) {
      std::fprintf(stderr, "tetrig-dds-cat: timeout: no frame for %lld ms\n", a.timeout_ms);
      exit_code = 2;
      done = true;
    }
  }

  // The counts on stderr (unless --quiet, or on a fault).
  void printSummary() const {
    if (!a.quiet || exit_code == 0)
      std::fprintf(stderr,
                   "tetrig-dds-cat: %" PRIu64 " frames (%" PRIu64 " missed, %" PRIu64 " refused, %" PRIu64 " before static data), %zu bytes per frame, "
                   "%" PRIu64 " static refused, %" PRIu64 " liveliness losses\n",
                   seen, missed, refused, before_static, bytes_per_frame, static_refused, lost);
  }

  // --latency-json: the counts and latency percentiles of the topic; false (said on stderr) when it
  // cannot be written.
  bool writeLatencyJson(const std::string& base, double seconds) const {
    std::FILE* out = std::fopen(a.latency_json.c_str(), "w");
    if (out == nullptr) return std::fprintf(stderr, "tetrig-dds-cat: cannot write %s: %s\n", a.latency_json.c_str(), std::strerror(errno)), false;
    std::fprintf(out,
                 "{ \"topic\": %s, \"frames_seen\": %" PRIu64 ", \"frames_missed\": %" PRIu64 ", \"frames_refused\": %" PRIu64
                 ", \"frames_before_static\": %" PRIu64 ", \"static_refused\": %" PRIu64 ", \"instances\": %" PRIu64
                 ", \"liveliness_lost\": %" PRIu64 ",\n  \"rig_name\": %s, \"vertex_count\": %u, \"bytes_per_frame\": %zu, \"seconds\": %.3f,\n"
                 "  \"latency_us\": {\n    \"receive_to_seen\": %s,\n    \"published_to_seen\": %s,\n    \"written_to_seen\": %s } }\n",
                 jsonString(tetrig::dds::frameTopicName(base)).c_str(), seen, missed, refused, before_static, static_refused, instances, lost,
                 jsonString(rig_name).c_str(), vertex_count, bytes_per_frame, seconds, statsJson(receive_to_seen).c_str(),
                 statsJson(published_to_seen).c_str(), statsJson(written_to_seen).c_str());
    if (std::fclose(out) != 0) return std::fprintf(stderr, "tetrig-dds-cat: cannot write %s\n", a.latency_json.c_str()), false;
    return true;
  }
};

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (const int status = parseArgs(argc, argv, a); status >= 0) return status;
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);

  std::FILE* dump = nullptr;
  if (!a.dump.empty()) {
    dump = std::fopen(a.dump.c_str(), "wb");
    if (dump == nullptr) return std::fprintf(stderr, "tetrig-dds-cat: cannot write %s: %s\n", a.dump.c_str(), std::strerror(errno)), 1;
    std::fwrite("TSHMDMP1", 1, 8, dump);
  }

  std::string base;
  try {
    base = tetrig::dds::topicBaseName(a.name);
  } catch (const tetrig::dds::DdsError& e) {
    return std::fprintf(stderr, "tetrig-dds-cat: %s\n", e.what()), 1;
  }
  tetrig::dds::DdsOptions options;
  options.domain_id = a.domain;
  const long long lease_ms = options.liveliness_lease_ns / 1'000'000;  // the publishers' lease: a reader must not ask for less
  std::unique_ptr<tetrig::dds::FrameSubscriber> sub;
  try {
    sub = std::make_unique<tetrig::dds::FrameSubscriber>(base, options);
  } catch (const tetrig::dds::DdsError& e) {
    return std::fprintf(stderr, "tetrig-dds-cat: %s\n", e.what()), 1;
  }
  if (!a.quiet) std::fprintf(stderr, "tetrig-dds-cat: waiting on %s\n", tetrig::dds::frameTopicName(base).c_str());

  Subscription s(a, dump, lease_ms);
  std::vector<tetrig::dds::SubscriberEvent> events;
  while (!s.done && g_stop == 0) s.poll(*sub, events);
  std::fflush(stdout);
  if (dump != nullptr && std::fclose(dump) != 0) {
    std::fprintf(stderr, "tetrig-dds-cat: cannot write %s: %s\n", a.dump.c_str(), std::strerror(errno));
    s.exit_code = 1;
  }
  const double seconds = static_cast<double>(tetrig::dds::monotonicNs() - s.start) * 1e-9;
  s.before_static += s.pending.size();  // never checked: their static data did not come
  s.printSummary();
  if (!a.latency_json.empty() && !s.writeLatencyJson(base, seconds)) return 1;
  return s.exit_code;
}
