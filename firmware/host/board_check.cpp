// Host check of the Teensyduino layer: the sketch (teensy/hasel_wheel_fw, compiled through
// host/sketch.cpp) and its board adapters, run against the mock Arduino API and its simulated
// board (host/mock_arduino).  Prints one line per check, "check <name>: pass" or
// "check <name>: fail (<first failed expectation>)", then a summary; exits 1 if any failed.
#include <cstdio>
#include <vector>

#include "Arduino.h"
#include "board.h"
#include "hasel_core/protocol.hpp"
#include "pins.h"

void setup();
void loop();

namespace {

// The first failed expectation of one check.
class Check {
 public:
  bool expect(bool ok, const char* what) {
    if (!ok && failed_ == nullptr) failed_ = what;
    return ok;
  }
  const char* failure() const { return failed_; }

 private:
  const char* failed_ = nullptr;
};

using Bytes = std::vector<uint8_t>;
using Messages = std::vector<hasel::Message>;

constexpr uint64_t kNever = ~uint64_t(0);
constexpr float kHvSetpointV = 9000.0f;

uint64_t now_us() { return mock::now_ns() / 1000u; }

// -- the simulated parts ----------------------------------------------------------------------

// An EMS22A frame: position, OCF, COF, LIN, Mag INC, Mag DEC, and the even-parity bit.
uint16_t ems_frame(uint16_t position, bool ocf = true, bool cof = false, bool lin = false,
                   bool mag_inc = false) {
  uint16_t f = uint16_t((position & 0x3FFu) << 6 | ocf << 5 | cof << 4 | lin << 3 | mag_inc << 2);
  bool odd = false;
  for (uint16_t v = f; v; v = uint16_t(v & (v - 1))) odd = !odd;
  return uint16_t(f | (odd ? 1u : 0u));
}

int counts_of(float value, float per_count) { return int(value / per_count + 0.5f); }

// Power the board up with the encoder at `position`, HV monitor at the set point, no
// current, and run setup().
void power_cycle(uint16_t position = 100) {
  mock::power_on();
  mock::set_encoder(ems_frame(position));
  mock::set_analog(pins::kHvMonitor, counts_of(kHvSetpointV, pins::kHvVoltsPerCount));
  mock::set_analog(pins::kCurrentMonitor, 0);
  mock::set_host_stalled(false);
  setup();
  mock::take_output();
}

// -- the host ---------------------------------------------------------------------------------

uint16_t host_counter = 0;

// One host frame, preceded by a 0x00 as the driver sends it.
void send(hasel::Message m) {
  m.counter = ++host_counter;
  uint8_t wire[hasel::kMaxWire + 1] = {0};
  size_t n = hasel::encode(m, wire + 1);
  mock::host_send(wire, n + 1);
}

hasel::Message hv(uint8_t enable) {
  hasel::Message m;
  m.type = hasel::kHv;
  m.enable = enable;
  return m;
}

hasel::Message command(uint32_t seq, uint8_t n_a, float phi_a, float phi_d) {
  hasel::Message m;
  m.type = hasel::kCommand;
  m.command_seq = seq;
  m.n_a = n_a;
  m.phi_a = phi_a;
  m.phi_d = phi_d;
  return m;
}

hasel::Message heartbeat() {
  hasel::Message m;
  m.type = hasel::kHeartbeat;
  m.host_time_us = now_us();
  return m;
}

hasel::Message config(uint16_t rate_hz) {
  hasel::Message m;
  m.type = hasel::kConfig;
  m.telemetry_rate_hz = rate_hz;
  m.watchdog_ms = 100;
  m.max_on_ms = 2000;
  return m;
}

Messages decode(const Bytes& wire, uint32_t* dropped = nullptr) {
  hasel::Decoder dec;
  Messages out;
  hasel::Message m;
  for (uint8_t b : wire) {
    if (dec.push(b, &m)) out.push_back(m);
  }
  const hasel::DecoderStats& s = dec.stats();
  if (dropped) {
    *dropped = s.crc_errors + s.framing_errors + s.oversize + s.version_errors + s.type_errors +
               s.length_errors;
  }
  return out;
}

bool is_ack(const hasel::Message& m, uint8_t type, uint16_t counter) {
  return m.type == hasel::kAck && m.ref_type == type && m.ref_counter == counter;
}

// Run loop() in 1 us steps until a tick runs (it flushes USB); returns the time of that pass
// and what the tick sent.
uint64_t next_tick(Bytes* out, uint64_t limit_us = 200000) {
  for (uint64_t i = 0; i < limit_us; ++i) {
    uint64_t t = now_us();
    uint32_t flushes = mock::flushes();
    loop();
    if (mock::flushes() != flushes) {
      *out = mock::take_output();
      return t;
    }
    mock::advance_us(1);
  }
  return kNever;
}

Messages tick_messages(uint64_t* t = nullptr) {
  Bytes out;
  uint64_t when = next_tick(&out);
  if (t) *t = when;
  return decode(out);
}

const hasel::Message* telemetry(Messages&&) = delete;   // it would point into a temporary
const hasel::Message* telemetry(const Messages& ms) {
  for (const hasel::Message& m : ms) {
    if (m.type == hasel::kTelemetry) return &m;
  }
  return nullptr;
}

// -- the checks -------------------------------------------------------------------------------

bool is_safety_pin(uint8_t pin) {
  const uint8_t safety[] = {pins::kTpicG, pins::kHvEnable, pins::kTpicClr, pins::kTpicSrck,
                            pins::kTpicRck, pins::kTpicSerIn};
  for (uint8_t p : safety) {
    if (p == pin) return true;
  }
  return false;
}

bool level_event(const mock::Event& e, uint8_t pin, int level) {
  return e.kind == mock::Kind::kLevel && e.pin == pin && e.level == level;
}

// (1) Every HV path is off after setup(), and setting it so were its first pin changes.
void check_safe_setup(Check& c) {
  mock::power_on();
  c.expect(mock::storage() != 0, "the simulated registers start with garbage");
  setup();
  const std::vector<mock::Event>& ev = mock::events();
  const mock::Snapshot& at = mock::at_serial_begin();
  c.expect(ev.size() > 2 && level_event(ev[0], pins::kTpicG, 1) &&
               level_event(ev[1], pins::kHvEnable, 0),
           "the first two pin changes are G high and HV enable low");
  size_t latch = ev.size();
  for (size_t i = 0; i < ev.size() && latch == ev.size(); ++i) {
    if (level_event(ev[i], pins::kTpicRck, 1)) latch = i;
  }
  c.expect(latch < ev.size(), "a latch pulse on RCK");
  bool cleared = false;
  for (size_t i = 0; i < latch && i < ev.size(); ++i) {
    cleared |= level_event(ev[i], pins::kTpicClr, 0);
  }
  c.expect(cleared, "CLR driven low before the latch");
  for (size_t i = 0; i < at.events && i < ev.size(); ++i) {
    c.expect(!level_event(ev[i], pins::kTpicG, 0) && !level_event(ev[i], pins::kTpicG, -1),
             "G stays high until Serial.begin");
    c.expect(ev[i].level == 0 || ev[i].pin != pins::kHvEnable,
             "HV enable stays low until Serial.begin");
    c.expect(i > latch || is_safety_pin(ev[i].pin),
             "no other pin changes before the zeros are latched");
  }
  c.expect(at.taken && at.events > latch, "Serial.begin after the latch");
  c.expect(at.storage == 0 && at.leds == 0 && at.hv_enable == 0 && at.g == 1,
           "registers zero, LEDs off, HV enable low, G high at Serial.begin");
  size_t begins = 0;
  for (const mock::Event& e : ev) begins += e.kind == mock::Kind::kSerialBegin;
  c.expect(begins == 1, "Serial.begin once");
  c.expect(mock::leds() == 0 && mock::storage() == 0, "every optocoupler off after setup()");
  c.expect(mock::level(pins::kHvEnable) == 0, "HV enable low after setup()");
}

// (2) shift_out_mask(1 << k) lights actuator k's LED and no other.
void check_shift_order(Check& c) {
  power_cycle();
  for (int k = 0; k < 16; ++k) {
    uint16_t mask = uint16_t(1u << k);
    board::shift_out_mask(mask);
    c.expect(mock::leds() == mask, "shift_out_mask(1 << k) lights actuator k only");
  }
  board::shift_out_mask(0);
  c.expect(mock::leds() == 0 && mock::storage() == 0, "shift_out_mask(0) lights none");
  c.expect(mock::level(pins::kTpicG) == 1, "G high while the mask is zero");
}

// (3) read_encoder takes a valid frame's position and rejects a broken one.
void check_encoder_frame(Check& c) {
  power_cycle();
  struct Case {
    const char* what;
    uint16_t frame;
    bool connected;
    bool ok;
  };
  const Case cases[] = {
      {"a valid frame is accepted with its position", ems_frame(677), true, true},
      {"position 0 is accepted", ems_frame(0), true, true},
      {"position 1023 is accepted", ems_frame(1023), true, true},
      {"Mag INC alone is accepted", ems_frame(300, true, false, false, true), true, true},
      {"bad parity is rejected", uint16_t(ems_frame(677) ^ 1u), true, false},
      {"OCF = 0 is rejected", ems_frame(677, false), true, false},
      {"COF = 1 is rejected", ems_frame(677, true, true), true, false},
      {"LIN = 1 is rejected", ems_frame(677, true, false, true), true, false},
      {"all zeros are rejected", 0, true, false},
      {"a disconnected encoder is rejected", ems_frame(677), false, false},
  };
  uint32_t reads = mock::encoder_reads();
  for (const Case& k : cases) {
    mock::set_encoder(k.frame, k.connected);
    uint16_t raw = 0xFFFF;
    bool ok = board::read_encoder(&raw);
    uint16_t want = k.ok ? uint16_t(k.frame >> 6) : uint16_t(0xFFFF);
    c.expect(ok == k.ok && raw == want, k.what);
  }
  size_t n = sizeof(cases) / sizeof(cases[0]);
  c.expect(mock::encoder_reads() - reads == n, "every read clocks 16 bits");
  c.expect(mock::encoder_timing_errors() == 0, "the EMS22A timing is met");
}

// (4) One tick with host bytes for HV enable and a COMMAND answers both and sends telemetry.
void check_tick_ack(Check& c) {
  power_cycle();
  send(hv(1));
  uint16_t hv_counter = host_counter;
  send(command(7, 3, 0.05f, 0.30f));
  uint64_t t = 0;
  Messages ms = tick_messages(&t);
  c.expect(ms.size() == 3, "three frames: two ACKs and a TELEMETRY");
  if (ms.size() != 3) return;
  c.expect(is_ack(ms[0], hasel::kHv, hv_counter), "ACK of the HV frame");
  c.expect(is_ack(ms[1], hasel::kCommand, host_counter) && ms[1].command_seq == 7,
           "ACK of the COMMAND with its command_seq");
  c.expect(ms[2].type == hasel::kTelemetry && ms[2].sample_seq == 1, "TELEMETRY, sample 1");
  c.expect(ms[2].device_time_us == t, "device time is the tick's micros()");
  c.expect(ms[2].encoder_raw == 100, "the encoder reading reaches the telemetry");
  c.expect(mock::host_pending() == 0, "every host byte was taken");
  c.expect(mock::level(pins::kHvEnable) == 1, "HV enable driven high");
  c.expect(mock::leds() == 0, "no pad before its angle");
}

// The COMMAND's pad switches on at its angle and off at its end, through the registers.
void check_tick_pad(Check& c) {
  power_cycle();
  send(hv(1));
  send(command(9, 3, 0.05f, 0.30f));   // pad 3: on at count 192 + 9, off at 192 + 49
  tick_messages();
  const hasel::Message* t = nullptr;
  Messages ms;
  for (uint16_t position : {150, 200}) {   // steps under the encoder track's glitch limit
    mock::set_encoder(ems_frame(position));
    ms = tick_messages();
    t = telemetry(ms);
    c.expect(t && t->q == 0 && mock::leds() == 0, "pad 3 off before its angle");
  }
  mock::set_encoder(ems_frame(210));
  ms = tick_messages();
  t = telemetry(ms);
  c.expect(t && t->q == 1 && t->active_mask == 8, "telemetry: pad 3 on");
  c.expect(mock::leds() == 8 && mock::level(pins::kTpicG) == 0, "actuator 3's LED lit");
  mock::set_encoder(ems_frame(245));
  ms = tick_messages();
  t = telemetry(ms);
  c.expect(t && t->q == 0 && t->active_mask == 0, "telemetry: pad 3 off");
  c.expect(mock::leds() == 0 && mock::level(pins::kTpicG) == 1, "every LED off again");
}

// (5) With no room left a frame is dropped whole; what is written decodes whole.
void check_drop_whole_frame(Check& c) {
  power_cycle();
  mock::set_host_stalled(true);   // USB packets pile up until availableForWrite() is 0
  int empty_ticks = 0;
  uint32_t broken = 0, last_seq = 0;
  int partial_ticks = 0;
  for (int k = 0; k < 20; ++k) {
    if (k > 0) send(heartbeat());  // then an ACK and a TELEMETRY per tick, a packet each
    Bytes out;
    c.expect(next_tick(&out) != kNever, "the tick runs while the host stalls");
    uint32_t dropped = 0;
    Messages ms = decode(out, &dropped);
    const hasel::Message* t = telemetry(ms);
    broken += dropped + (!out.empty() && out.back() != 0);
    if (out.empty()) ++empty_ticks;
    if (!ms.empty() && !t) ++partial_ticks;
    if (t) last_seq = t->sample_seq;
  }
  c.expect(empty_ticks > 0, "frames are dropped once the USB queue is full");
  c.expect(partial_ticks > 0, "an ACK that fits is sent when the TELEMETRY after it is not");
  c.expect(broken == 0, "every byte written belongs to a whole frame");
  c.expect(mock::tx_overruns() == 0, "never a write that would wait");
  mock::set_host_stalled(false);
  mock::take_output();
  Messages after = tick_messages();
  const hasel::Message* t = telemetry(after);
  c.expect(last_seq < 20 && t && t->sample_seq == 21,
           "after the stall TELEMETRY arrives again, with a gap in sample_seq");
}

// Host bytes that do not fit the core's buffer wait in USB for the next tick.
void check_rx_leftover(Check& c) {
  power_cycle();
  const Bytes zeros(600, 0);   // empty chunks: more than the core's receive buffer
  mock::host_send(zeros.data(), zeros.size());
  send(hv(1));
  size_t sent = mock::host_pending();
  Messages ms = tick_messages();
  size_t left = mock::host_pending();
  c.expect(left > 0 && left < sent, "part of the bytes wait in USB");
  c.expect(ms.size() == 1, "only TELEMETRY on the first tick");
  ms = tick_messages();
  c.expect(mock::host_pending() == 0, "the rest is taken at the next tick");
  c.expect(ms.size() == 2 && is_ack(ms[0], hasel::kHv, host_counter), "the frame behind is ACKed");
}

// Ticks at 300 Hz (exact on average), then at a CONFIG's new rate from the next tick on.
void check_tick_rate(Check& c) {
  power_cycle();
  uint64_t t[4];
  for (uint64_t& ti : t) tick_messages(&ti);
  c.expect(t[3] - t[0] == 10000, "three periods at 300 Hz take 10 ms");
  for (int i = 1; i < 4; ++i) {
    c.expect(t[i] - t[i - 1] == 3333 || t[i] - t[i - 1] == 3334, "a period is 3333 or 3334 us");
  }
  send(config(500));
  uint64_t a = 0, b = 0, d = 0;
  Messages ms = tick_messages(&a);
  c.expect(!ms.empty() && is_ack(ms[0], hasel::kConfig, host_counter), "CONFIG is ACKed");
  tick_messages(&b);
  tick_messages(&d);
  c.expect(b - a == 2000 && d - b == 2000, "then a period is 2000 us");
}

// The core's watchdog reaches the pin: HV enable goes low 100 ms after the last host frame.
void check_watchdog_pin(Check& c) {
  power_cycle();
  send(hv(1));
  uint64_t t0 = 0;
  tick_messages(&t0);
  c.expect(mock::level(pins::kHvEnable) == 1, "HV enable high");
  uint64_t t = t0;
  while (mock::level(pins::kHvEnable) == 1 && t - t0 < 200000) {
    Messages ms = tick_messages(&t);
    const hasel::Message* tel = telemetry(ms);
    if (mock::level(pins::kHvEnable) == 0) {
      c.expect(tel && (tel->fault_flags & hasel::kFaultWatchdog), "watchdog fault reported");
    }
  }
  c.expect(t - t0 >= 100000 && t - t0 < 100000 + 3334,
           "HV enable low at the first tick after 100 ms");
  c.expect(mock::level(pins::kHvEnable) == 0, "HV enable low");
}

// The chip's watchdog runs from setup() on with 100 ms, every tick refreshes it, and a loop()
// that stops refreshing it lets it expire (the chip resets: safe outputs again).
void check_hardware_watchdog(Check& c) {
  power_cycle();
  c.expect(mock::watchdog_enabled() && mock::watchdog_timeout_ms() == 100,
           "watchdog enabled by setup() with 100 ms");
  uint32_t before = mock::watchdog_refreshes();
  uint64_t t = 0, t0 = 0;
  tick_messages(&t0);
  for (t = t0; t - t0 < 1000000;) tick_messages(&t);
  c.expect(!mock::watchdog_expired(), "not expired while ticking");
  c.expect(mock::watchdog_refreshes() - before >= 300, "refreshed at every tick");
  mock::advance_us(99000);
  c.expect(!mock::watchdog_expired(), "not expired within 100 ms of the last tick");
  mock::advance_us(2000);
  c.expect(mock::watchdog_expired(), "expired 101 ms after the last tick");
}

// device_time_us() runs on across micros()'s 32-bit wrap.
void check_clock_wrap(Check& c) {
  uint64_t now = now_us();
  uint64_t wrap = ((now >> 32) + 1) << 32;
  mock::advance_us(wrap - 3 - now);
  uint64_t before = board::device_time_us();
  mock::advance_us(10);
  uint64_t after = board::device_time_us();
  c.expect(after - before == 10 && after == now_us(), "64-bit time across the wrap");
  power_cycle();
  Messages ms = tick_messages();
  const hasel::Message* t = telemetry(ms);
  c.expect(t && t->device_time_us >= wrap, "telemetry time past 2^32 us");
}

}  // namespace

int main() {
  struct Entry {
    const char* name;
    void (*run)(Check&);
  };
  const Entry checks[] = {
      {"safe_setup", check_safe_setup},         {"shift_order", check_shift_order},
      {"encoder_frame", check_encoder_frame},   {"tick_ack", check_tick_ack},
      {"drop_whole_frame", check_drop_whole_frame}, {"tick_pad", check_tick_pad},
      {"rx_leftover", check_rx_leftover},       {"tick_rate", check_tick_rate},
      {"watchdog_pin", check_watchdog_pin},     {"clock_wrap", check_clock_wrap},
      {"hardware_watchdog", check_hardware_watchdog},
  };
  int failed = 0;
  for (const Entry& e : checks) {
    Check c;
    e.run(c);
    if (c.failure()) {
      ++failed;
      std::printf("check %s: fail (%s)\n", e.name, c.failure());
    } else {
      std::printf("check %s: pass\n", e.name);
    }
  }
  std::printf("summary: %d of %zu checks failed\n", failed, sizeof(checks) / sizeof(checks[0]));
  return failed ? 1 : 0;
}
