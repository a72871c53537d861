#include "board.h"

#include <Arduino.h>

#include "pins.h"

namespace board {
namespace {

// Half period of the bit-banged clocks and the wait after each edge [us].  TPIC6C596 set-up,
// hold and pulse widths are tens of ns; EMS22A: CS low to the first CLK falling edge >= 500 ns,
// CLK low and high >= 500 ns each, DO valid within 375 ns of the CLK rising edge, CS high
// >= 500 ns between reads.  1 us meets all of them.
constexpr uint32_t kEdgeUs = 1;
constexpr int kFrameBits = 16;

// EMS22A status bits of the 16-bit frame (bit 0 is the parity bit).
constexpr uint16_t kOcf = 1u << 5;
constexpr uint16_t kCof = 1u << 4;
constexpr uint16_t kLin = 1u << 3;
constexpr int kPositionShift = 6;

// Set the output level, then make the pin an output: it never drives any other level
// (digitalWriteFast sets the output data register even while the pin is an input).
void drive(uint8_t pin, uint8_t level) {
  digitalWriteFast(pin, level);
  pinMode(pin, OUTPUT);
}

void pulse(uint8_t pin) {
  digitalWriteFast(pin, HIGH);
  delayMicroseconds(kEdgeUs);
  digitalWriteFast(pin, LOW);
}

// Bit 15 goes first: after 16 clocks it sits in U2 DRAIN7 (actuator 15), bit 0 in U1 DRAIN0.
void shift_and_latch(uint16_t mask) {
  for (int bit = kFrameBits - 1; bit >= 0; --bit) {
    digitalWriteFast(pins::kTpicSerIn, ((mask >> bit) & 1u) ? HIGH : LOW);
    delayMicroseconds(kEdgeUs);
    pulse(pins::kTpicSrck);
  }
  delayMicroseconds(kEdgeUs);
  pulse(pins::kTpicRck);
}

uint16_t read_ems22a_frame() {
  digitalWriteFast(pins::kEncCs, LOW);
  delayMicroseconds(kEdgeUs);
  uint16_t frame = 0;
  for (int i = 0; i < kFrameBits; ++i) {
    digitalWriteFast(pins::kEncClk, LOW);
    delayMicroseconds(kEdgeUs);
    digitalWriteFast(pins::kEncClk, HIGH);   // the encoder shifts the next bit out
    delayMicroseconds(kEdgeUs);
    frame = uint16_t((frame << 1) | (digitalRead(pins::kEncDo) ? 1u : 0u));
  }
  digitalWriteFast(pins::kEncCs, HIGH);
  delayMicroseconds(kEdgeUs);
  return frame;
}

bool even_parity(uint16_t v) {
  bool odd = false;
  for (; v; v = uint16_t(v & (v - 1))) odd = !odd;
  return !odd;
}

}  // namespace

void safe_outputs() {
  drive(pins::kTpicG, HIGH);
  drive(pins::kHvEnable, LOW);
  drive(pins::kTpicClr, LOW);
  drive(pins::kTpicSrck, LOW);
  drive(pins::kTpicRck, LOW);
  drive(pins::kTpicSerIn, LOW);
  delayMicroseconds(kEdgeUs);
  digitalWriteFast(pins::kTpicClr, HIGH);
  shift_and_latch(0);
}

void start_watchdog(uint32_t timeout_ms) {
  noInterrupts();
  WDOG_UNLOCK = WDOG_UNLOCK_SEQ1;   // the unlock pair, then the configuration within 256
  WDOG_UNLOCK = WDOG_UNLOCK_SEQ2;   // bus clocks
  __asm__ volatile("nop");
  __asm__ volatile("nop");
  WDOG_TOVALH = uint16_t(timeout_ms >> 16);
  WDOG_TOVALL = uint16_t(timeout_ms);
  WDOG_PRESC = 0;                   // LPO 1 kHz, not divided: one count per ms
  WDOG_STCTRLH = WDOG_STCTRLH_ALLOWUPDATE | WDOG_STCTRLH_WDOGEN | WDOG_STCTRLH_WAITEN |
                 WDOG_STCTRLH_STOPEN;
  interrupts();
}

void feed_watchdog() {
  noInterrupts();                   // the refresh pair must follow within 20 bus clocks
  WDOG_REFRESH = 0xA602;
  WDOG_REFRESH = 0xB480;
  interrupts();
}

void begin_inputs() {
  drive(pins::kEncCs, HIGH);
  drive(pins::kEncClk, HIGH);
  pinMode(pins::kEncDo, INPUT_PULLUP);
  analogReadResolution(pins::kAdcBits);
}

void shift_out_mask(uint16_t mask) {
  shift_and_latch(mask);
  digitalWriteFast(pins::kTpicG, mask ? LOW : HIGH);
}

void set_hv_supply(bool on) { digitalWriteFast(pins::kHvEnable, on ? HIGH : LOW); }

bool parse_encoder_frame(uint16_t frame, uint16_t* position) {
  bool ok = even_parity(frame) && (frame & kOcf) && !(frame & kCof) && !(frame & kLin);
  if (ok) *position = uint16_t(frame >> kPositionShift);
  return ok;
}

bool read_encoder(uint16_t* raw) { return parse_encoder_frame(read_ems22a_frame(), raw); }

float read_hv_volts() { return float(analogRead(pins::kHvMonitor)) * pins::kHvVoltsPerCount; }

float read_current_amps() {
  return float(analogRead(pins::kCurrentMonitor)) * pins::kCurrentAmpsPerCount;
}

uint64_t device_time_us() {
  static uint32_t last = 0;
  static uint64_t wraps = 0;   // whole 2^32 us periods
  uint32_t now = micros();
  if (now < last) wraps += uint64_t(1) << 32;
  last = now;
  return wraps + now;
}

void UsbSink::frame(const uint8_t* wire, size_t n) {
  int room = Serial.availableForWrite();
  if (room > 0 && size_t(room) < n) {   // a partly filled packet: send it, ask again
    Serial.send_now();
    room = Serial.availableForWrite();
  }
  if (room <= 0 || size_t(room) < n) {
    ++dropped_;
    return;
  }
  Serial.write(wire, n);
}

void TickClock::start(uint64_t now_us) {
  next_us_ = now_us;
  carry_ = 0;
  rate_hz_ = 0;
}

void TickClock::advance(uint64_t now_us, uint16_t rate_hz) {
  constexpr uint32_t kUsPerS = 1000000;
  if (rate_hz == 0) rate_hz = 1;   // the core keeps 50..1000 Hz; never divide by zero
  if (rate_hz != rate_hz_) {
    rate_hz_ = rate_hz;
    carry_ = 0;
  }
  next_us_ += kUsPerS / rate_hz;
  carry_ += kUsPerS % rate_hz;
  if (carry_ >= rate_hz) {
    carry_ -= rate_hz;
    ++next_us_;
  }
  if (next_us_ <= now_us) {        // a period or more late: restart from now
    next_us_ = now_us + kUsPerS / rate_hz;
    carry_ = 0;
  }
}

}  // namespace board
