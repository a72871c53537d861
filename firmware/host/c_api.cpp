// A C interface to the portable core for the host: the test suite loads it with ctypes
// (hasel_wheel_sim.device_cpp) and drives the core tick by tick.  Not part of the Teensy build.
#include <cstddef>
#include <cstdint>
#include <new>

#include "hasel_core/device.hpp"
#include "hasel_core/protocol.hpp"

namespace {

// Collects a tick's frames into the caller's buffer; a frame that does not fit is dropped.
struct BufferSink final : hasel::FrameSink {
  uint8_t* out;
  size_t cap;
  size_t len = 0;
  uint32_t dropped = 0;
  BufferSink(uint8_t* o, size_t c) : out(o), cap(c) {}
  void frame(const uint8_t* wire, size_t n) override {
    if (n > cap - len) {
      ++dropped;
      return;
    }
    for (size_t i = 0; i < n; ++i) out[len++] = wire[i];
  }
};

}  // namespace

extern "C" {

struct hw_sensors {
  uint16_t encoder_raw;
  uint8_t encoder_ok;
  float hv_monitor;
  float current_monitor;
};

struct hw_outputs {
  uint16_t active_mask;
  uint8_t hv_supply;
  uint16_t telemetry_rate_hz;
  uint32_t dropped;   // frames that did not fit the caller's buffer
};

// The device state as 64-bit integers and doubles, in DeviceState's order.
struct hw_latched {
  int64_t valid, seq, n_a;
  double phi_a, phi_d;
  int64_t sector, on_count, off_count, now;
};

struct hw_state {
  int64_t hv_enabled, estop, faults, counter, sample_seq, last_host_us, hv_on_since_us,
      on_since_us, q, eta_unwrapped, last_command_seq;
  hw_latched pending, target;
  int64_t telemetry_rate_hz, watchdog_ms, max_on_ms, drain_mode;
  int64_t encoder_started, encoder_unwrapped, encoder_bad_run;
};

size_t hw_message_size() { return sizeof(hasel::Message); }

void* hw_device_new() { return new (std::nothrow) hasel::Device(); }
void hw_device_free(void* d) { delete static_cast<hasel::Device*>(d); }
void hw_device_reset(void* d) { static_cast<hasel::Device*>(d)->reset(); }

size_t hw_device_receive(void* d, const uint8_t* data, size_t n) {
  return static_cast<hasel::Device*>(d)->receive(data, n);
}

size_t hw_device_tick(void* d, uint64_t now_us, const hw_sensors* in, uint8_t* tx, size_t cap,
                      hw_outputs* out) {
  hasel::Sensors s;
  s.encoder_raw = in->encoder_raw;
  s.encoder_ok = in->encoder_ok != 0;
  s.hv_monitor = in->hv_monitor;
  s.current_monitor = in->current_monitor;
  BufferSink sink(tx, cap);
  hasel::Outputs o = static_cast<hasel::Device*>(d)->tick(now_us, s, sink);
  out->active_mask = o.active_mask;
  out->hv_supply = o.hv_supply ? 1 : 0;
  out->telemetry_rate_hz = o.telemetry_rate_hz;
  out->dropped = sink.dropped;
  return sink.len;
}

static void copy_latched(const hasel::Latched& l, hw_latched* o) {
  *o = hw_latched{l.valid, l.seq, l.n_a, l.phi_a, l.phi_d, l.sector, l.on_count, l.off_count,
                  l.now};
}

void hw_device_state(void* d, hw_state* o) {
  const auto* dev = static_cast<hasel::Device*>(d);
  const hasel::DeviceState& s = dev->state();
  o->hv_enabled = s.hv_enabled;
  o->estop = s.estop;
  o->faults = s.faults;
  o->counter = s.counter;
  o->sample_seq = s.sample_seq;
  o->last_host_us = int64_t(s.last_host_us);
  o->hv_on_since_us = int64_t(s.hv_on_since_us);
  o->on_since_us = int64_t(s.on_since_us);
  o->q = s.q;
  o->eta_unwrapped = s.eta_unwrapped;
  o->last_command_seq = s.last_command_seq;
  copy_latched(s.pending, &o->pending);
  copy_latched(s.target, &o->target);
  o->telemetry_rate_hz = s.telemetry_rate_hz;
  o->watchdog_ms = s.watchdog_ms;
  o->max_on_ms = s.max_on_ms;
  o->drain_mode = s.drain_mode;
  o->encoder_started = dev->encoder().started();
  o->encoder_unwrapped = dev->encoder().unwrapped();
  o->encoder_bad_run = dev->encoder().bad_run();
}

// -- codec -------------------------------------------------------------------------------
uint16_t hw_crc16(const uint8_t* data, size_t n) { return hasel::crc16(data, n); }
int32_t hw_angle_counts(float phi) { return hasel::angle_counts(phi); }
size_t hw_encode(const hasel::Message* m, uint8_t* out) { return hasel::encode(*m, out); }
size_t hw_cobs_encode(const uint8_t* in, size_t n, uint8_t* out) { return hasel::cobs_encode(in, n, out); }
int hw_cobs_decode(const uint8_t* in, size_t n, uint8_t* out) { return hasel::cobs_decode(in, n, out); }

void* hw_decoder_new() { return new (std::nothrow) hasel::Decoder(); }
void hw_decoder_free(void* d) { delete static_cast<hasel::Decoder*>(d); }

// Feed bytes; up to cap decoded messages go to out; returns how many frames completed.
size_t hw_decoder_feed(void* d, const uint8_t* data, size_t n, hasel::Message* out, size_t cap) {
  auto* dec = static_cast<hasel::Decoder*>(d);
  size_t k = 0;
  hasel::Message m;
  for (size_t i = 0; i < n; ++i) {
    if (dec->push(data[i], &m)) {
      if (k < cap) out[k] = m;
      ++k;
    }
  }
  return k;
}

void hw_decoder_stats(void* d, hasel::DecoderStats* out) {
  *out = static_cast<hasel::Decoder*>(d)->stats();
}

}  // extern "C"
