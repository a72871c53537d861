// The 10-bit absolute encoder's readings unwrapped into a count that keeps growing across
// turns, robust to a glitched reading.  Portable C++17.
#pragma once
#include <cstdint>

namespace hasel {

constexpr int32_t kEncoderCounts = 1024;   // counts per revolution
// A reading more than this many counts from the last good one, per tick since it, is a glitch
// (pi/8 rad per tick: 118 rad/s at 300 Hz, far beyond any rolling wheel) [counts].
constexpr int32_t kMaxStepCounts = 64;
// Consecutive bad readings after which the position counts as lost: HV goes off, and the
// next good reading is taken as it is [ticks].
constexpr uint16_t kLostAfter = 10;

struct EncoderStep {
  bool good = false;      // this reading was taken (not failed, not a glitch)
  bool lost = false;      // kLostAfter bad readings in a row: the position is not known
  int32_t unwrapped = 0;  // unwrapped count of the last good reading
};

class EncoderTrack {
 public:
  // Take one reading (raw 0..1023; ok false when the read itself failed).
  EncoderStep update(uint16_t raw, bool ok);
  void reset() { *this = EncoderTrack(); }
  bool started() const { return started_; }
  int32_t unwrapped() const { return unwrapped_; }
  uint16_t bad_run() const { return bad_run_; }

 private:
  bool started_ = false;
  int32_t unwrapped_ = 0;
  uint16_t last_raw_ = 0;
  uint16_t bad_run_ = 0;
};

}  // namespace hasel
