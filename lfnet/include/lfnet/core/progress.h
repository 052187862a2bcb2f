// A progress bar with rate and ETA for long work, on stderr.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace lfnet {

// Draws "label [#####.....] 412/1000 41% 230.1/s ETA 0:02 loss 0.012" on stderr, redrawn in
// place on a terminal at most 10 times a second. Off a terminal (a log file) it prints a line
// at most every 5 seconds, and a last line for work that took a second or more. The rate counts
// from construction: make the bar when the work starts (set_total() when the size is known
// later).
// Silent when disabled (set_progress_enabled(false), e.g. in tests or with --log-level off).
class ProgressBar {
 public:
  ProgressBar(std::string label, int64_t total, std::string unit = "");
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  void advance(int64_t n = 1);
  // The amount of work, when it is known only once the work has started.
  void set_total(int64_t total) { total_ = total; }
  // Text shown after the ETA, e.g. the current loss.
  void set_note(std::string note);
  // Draws the final state and ends the line; called by the destructor if not before.
  void finish();
  double elapsed_seconds() const;

 private:
  void draw(bool force);

  std::string label_, unit_, note_;
  int64_t total_, done_ = 0;
  bool finished_ = false, tty_, drawn_ = false;
  std::chrono::steady_clock::time_point start_, last_draw_;
};

// Globally enables or disables progress bars (enabled by default).
void set_progress_enabled(bool enabled);
bool progress_enabled();

// Seconds since construction.
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  void reset() { start_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace lfnet
