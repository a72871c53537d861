// Board adapters of the wheel's Teensy 3.6: the TPIC6C596 shift registers, the EMS22A
// encoder, the HV and current monitors, the HV converter's supply, USB serial and the clock.
// Arduino API only (pinMode, digitalWriteFast, digitalRead, analogRead, delayMicroseconds,
// micros, Serial), so the same code builds for the Teensy and against the host mock.
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "hasel_core.h"

namespace board {

// Every HV path off; the first thing setup() does.  G high (every drain off) and the HV
// supply's EN low, each set before its pin becomes an output so it never shows another level;
// then CLR low clears both registers, and a 16-bit zero is shifted in and latched.  G stays
// high.
void safe_outputs();

// The chip's own watchdog (Kinetis WDOG on the 1 kHz LPO clock): it resets the Teensy, and so
// runs safe_outputs() again, unless feed_watchdog() is called within timeout_ms.  A hung tick
// then cannot leave a pad or the HV supply on.
void start_watchdog(uint32_t timeout_ms);
void feed_watchdog();

// Encoder lines idle (CS high, CLK high, DO input with pull-up: a missing encoder reads all
// ones, which fails the status check) and the ADC at pins::kAdcBits.
void begin_inputs();

// Shift `mask` into the registers and latch it: bit k lights actuator k's optocoupler.
// G is low only while the mask is not zero.
void shift_out_mask(uint16_t mask);

// The HV converter's 24 V supply (U3V50F24 EN) on or off.
void set_hv_supply(bool on);

// One EMS22A read.  True when the frame is valid; then *raw is its position (0..1023).
// *raw is left unchanged otherwise.
bool read_encoder(uint16_t* raw);

// The checks of one 16-bit EMS22A frame, MSB first: D9..D0, OCF, COF, LIN, Mag INC, Mag DEC,
// even parity.  Valid: even parity over all 16 bits, OCF = 1 (offset compensation finished),
// COF = 0 (no CORDIC overflow), LIN = 0 (no linearity alarm).  Mag INC and Mag DEC alone are
// informational.  Writes the position when valid.
bool parse_encoder_frame(uint16_t frame, uint16_t* position);

// The monitors, scaled with the calibration values of pins.h.
float read_hv_volts();      // [V]
float read_current_amps();  // [A]

// Device time [us] since power-up: micros() extended to 64 bits.  Call at least once per
// 71 minutes (2^32 us); loop() calls it on every pass.
uint64_t device_time_us();

// The core's frames to USB serial: a frame is written whole when the transmit buffer has room
// for all of it, else dropped (protocol section 6, "Senders"); it never waits.  Teensy 3.x
// reports as room only what is left in its current 64-byte USB packet: when that is too
// little, the packet is handed to USB (send_now) and the room of a fresh one is asked for.
class UsbSink final : public hasel::FrameSink {
 public:
  void frame(const uint8_t* wire, size_t n) override;
  uint32_t dropped() const { return dropped_; }

 private:
  uint32_t dropped_ = 0;
};

// Tick deadlines at a rate [Hz] exact on average: 10^6 / rate [us] per period, the remainder
// carried.  After a stall of more than one period it restarts from now (no burst of ticks).
class TickClock {
 public:
  void start(uint64_t now_us);               // the first tick is due at now_us
  bool due(uint64_t now_us) const { return now_us >= next_us_; }
  // After a tick: the next deadline, one period of rate_hz (the core's, read after the tick)
  // after this one.
  void advance(uint64_t now_us, uint16_t rate_hz);

 private:
  uint64_t next_us_ = 0;
  uint32_t carry_ = 0;    // accumulated remainder of 10^6 / rate_hz_ [us * rate_hz_]
  uint16_t rate_hz_ = 0;
};

}  // namespace board
