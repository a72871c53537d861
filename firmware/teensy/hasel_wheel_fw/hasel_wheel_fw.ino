// HASEL rolling soft wheel, Teensy 3.6 (USB type: Serial).  Glue between the board adapters
// (board.h, pins.h) and the portable core (hasel::Device, firmware/core), which holds every
// rule of protocol v1 (docs/protocol.md).  This file schedules the tick and moves bytes,
// readings and outputs; it decides nothing.
//
// Scheduling: loop() polls a deadline on the 64-bit device clock; no IntervalTimer.  A tick
// bit-bangs the encoder and the shift registers with microsecond waits (about 70 us) and
// uses USB serial, which an interrupt handler should not do while the main program might.
// Polling keeps all of it in one context with no shared state, and loop() does nothing else,
// so a tick starts within one loop() pass of its deadline.
#include <Arduino.h>

#include "hasel_core.h"  // first: Arduino CLI finds the core library by this header
#include "board.h"

// The chip resets (all outputs safe again) when no tick has refreshed its watchdog for this
// long [ms]: the protocol's default host watchdog.
constexpr uint32_t kHardwareWatchdogMs = 100;

static hasel::Device wheel;           // the device rules (protocol section 4)
static board::UsbSink usb_sink;       // frames to USB serial, whole or dropped
static board::TickClock tick_clock;   // tick deadlines at the core's telemetry rate

// Host bytes into the core, as many as it has room for; the rest stays in the USB buffers.
static void feed_host_bytes() {
  uint8_t chunk[64];
  for (;;) {
    size_t n = size_t(Serial.available());
    if (n > wheel.rx_room()) n = wheel.rx_room();
    if (n > sizeof chunk) n = sizeof chunk;
    if (n == 0) return;
    n = Serial.readBytes(reinterpret_cast<char*>(chunk), n);   // available: no waiting
    wheel.receive(chunk, n);
  }
}

static hasel::Sensors read_sensors() {
  hasel::Sensors s;
  uint16_t raw = 0;
  s.encoder_ok = board::read_encoder(&raw);
  s.encoder_raw = raw;
  s.hv_monitor = board::read_hv_volts();
  s.current_monitor = board::read_current_amps();
  return s;
}

// Drive the outputs until the next tick.  No pad without HV, and never more than one pad:
// a mask that breaks either is not applied (the core never sends one).
static void apply(const hasel::Outputs& out) {
  uint16_t mask = out.hv_supply ? out.active_mask : 0;
  if (mask & (mask - 1)) mask = 0;
  board::shift_out_mask(mask);
  board::set_hv_supply(out.hv_supply);
}

void setup() {
  board::safe_outputs();   // first: every optocoupler off, HV converter supply off
  board::begin_inputs();
  Serial.begin(115200);    // USB CDC: the rate is ignored
  wheel.reset();
  board::start_watchdog(kHardwareWatchdogMs);
  tick_clock.start(board::device_time_us());
}

void loop() {
  uint64_t now = board::device_time_us();
  if (!tick_clock.due(now)) return;
  feed_host_bytes();
  hasel::Sensors sensors = read_sensors();
  hasel::Outputs out = wheel.tick(now, sensors, usb_sink);
  apply(out);
  tick_clock.advance(now, out.telemetry_rate_hz);
  Serial.send_now();       // send this tick's frames now, not when Teensy's flush timer expires
  board::feed_watchdog();
}
