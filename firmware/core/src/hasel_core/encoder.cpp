#include "hasel_core/encoder.hpp"

namespace hasel {

EncoderStep EncoderTrack::update(uint16_t raw, bool ok) {
  if (!ok || raw >= kEncoderCounts) {
    if (bad_run_ < 0xFFFF) ++bad_run_;
    return EncoderStep{false, bad_run_ >= kLostAfter, unwrapped_};
  }
  if (!started_ || bad_run_ >= kLostAfter) {
    // first reading, or the position was lost: take the reading, nearest wrap to the last
    int32_t d = started_ ? int32_t(raw) - int32_t(last_raw_) : 0;
    d = ((d % kEncoderCounts) + kEncoderCounts + kEncoderCounts / 2) % kEncoderCounts - kEncoderCounts / 2;
    unwrapped_ = started_ ? unwrapped_ + d : int32_t(raw);
    started_ = true;
    last_raw_ = raw;
    bad_run_ = 0;
    return EncoderStep{true, false, unwrapped_};
  }
  // the step from the last good reading, wrapped into [-512, 511]
  int32_t d = int32_t(raw) - int32_t(last_raw_);
  d = ((d % kEncoderCounts) + kEncoderCounts + kEncoderCounts / 2) % kEncoderCounts - kEncoderCounts / 2;
  int32_t limit = kMaxStepCounts * (int32_t(bad_run_) + 1);
  if (d > limit || d < -limit) {
    if (bad_run_ < 0xFFFF) ++bad_run_;
    return EncoderStep{false, bad_run_ >= kLostAfter, unwrapped_};
  }
  unwrapped_ += d;
  last_raw_ = raw;
  bad_run_ = 0;
  return EncoderStep{true, false, unwrapped_};
}

}  // namespace hasel
