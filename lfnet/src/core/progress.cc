#include "lfnet/core/progress.h"

#include <unistd.h>

#include <atomic>
#include <cstdio>

namespace lfnet {

namespace {
std::atomic<bool> g_enabled{true};

std::string clock_text(double seconds) {
  if (!(seconds >= 0) || seconds > 1e7) return "?";
  auto s = static_cast<int64_t>(seconds + 0.5);
  char buf[32];
  if (s >= 3600) {
    std::snprintf(buf, sizeof buf, "%lld:%02lld:%02lld", static_cast<long long>(s / 3600),
                  static_cast<long long>(s / 60 % 60), static_cast<long long>(s % 60));
  } else {
    std::snprintf(buf, sizeof buf, "%lld:%02lld", static_cast<long long>(s / 60),
                  static_cast<long long>(s % 60));
  }
  return buf;
}
}  // namespace

void set_progress_enabled(bool enabled) { g_enabled = enabled; }
bool progress_enabled() { return g_enabled; }

ProgressBar::ProgressBar(std::string label, int64_t total, std::string unit)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      total_(total),
      tty_(::isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::advance(int64_t n) {
  done_ += n;
  draw(false);
}

void ProgressBar::set_note(std::string note) { note_ = std::move(note); }

double ProgressBar::elapsed_seconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void ProgressBar::finish() {
  if (finished_) return;
  draw(true);
  finished_ = true;
  if (g_enabled && tty_) std::fputc('\n', stderr);
}

void ProgressBar::draw(bool force) {
  if (!g_enabled || finished_) return;
  const auto now = std::chrono::steady_clock::now();
  const double frac = total_ > 0 ? static_cast<double>(done_) / static_cast<double>(total_) : 1.0;
  if (tty_) {
    if (!force && now - last_draw_ < std::chrono::milliseconds(100)) return;
  } else if (force) {
    if (!drawn_ && now - start_ < std::chrono::seconds(1)) return;  // quick work: no line
  } else if (now - last_draw_ < std::chrono::seconds(5)) {
    return;
  }
  last_draw_ = now;
  drawn_ = true;
  const double elapsed = elapsed_seconds();
  const double rate = elapsed > 0 ? static_cast<double>(done_) / elapsed : 0.0;
  const double eta = rate > 0 ? static_cast<double>(total_ - done_) / rate : -1;
  constexpr int kWidth = 24;
  std::string bar(kWidth, '.');
  for (int i = 0; i < static_cast<int>(frac * kWidth) && i < kWidth; ++i) bar[i] = '#';
  std::fprintf(stderr, "%s%s [%s] %lld/%lld %3.0f%% %.1f%s/s %s %s%s%s", tty_ ? "\r" : "",
               label_.c_str(), bar.c_str(), static_cast<long long>(done_),
               static_cast<long long>(total_), 100 * frac, rate,
               unit_.empty() ? "" : (" " + unit_).c_str(), done_ >= total_ ? "in" : "ETA",
               clock_text(done_ >= total_ ? elapsed : eta).c_str(), note_.empty() ? "" : "  ",
               note_.c_str());
  if (!tty_) std::fputc('\n', stderr);
  std::fflush(stderr);
}

}  // namespace lfnet
