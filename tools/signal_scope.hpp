// SIGINT, SIGTERM and SIGHUP (a closed terminal or ssh session) noted for the lifetime of a scope instead of ending the process, so that a
// long command (tetrig run, tetrig export) stops between two frames, says why, and cleans up
// (temporary files, the shared-memory segment). The previous handlers come back when the scope ends.
// One scope at a time: the handler and the noted signal are process-wide.
#pragma once

#include <signal.h>

#include <csignal>

namespace tetrig::tools {

inline volatile std::sig_atomic_t g_stop_signal = 0;

extern "C" inline void tetrigNoteStopSignal(int signal_number) { g_stop_signal = signal_number; }

class StopSignalScope {
 public:
  StopSignalScope() {
    g_stop_signal = 0;
    struct sigaction action {};
    action.sa_handler = tetrigNoteStopSignal;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, &old_int_);
    sigaction(SIGTERM, &action, &old_term_);
    sigaction(SIGHUP, &action, &old_hup_);
  }
  ~StopSignalScope() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
    sigaction(SIGHUP, &old_hup_, nullptr);
  }
  StopSignalScope(const StopSignalScope&) = delete;
  StopSignalScope& operator=(const StopSignalScope&) = delete;

  // The signal received since the scope began (SIGINT, SIGTERM or SIGHUP), or 0.
  static int pending() noexcept { return g_stop_signal; }
  // "interrupted (SIGINT)", "hung up (SIGHUP)" or "terminated (SIGTERM)".
  static const char* describe(int signal_number) noexcept {
    return signal_number == SIGINT ? "interrupted (SIGINT)" : signal_number == SIGHUP ? "hung up (SIGHUP)" : "terminated (SIGTERM)";
  }

 private:
  struct sigaction old_int_ {}, old_term_ {}, old_hup_ {};
};

}  // namespace tetrig::tools
