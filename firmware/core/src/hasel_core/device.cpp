#include "hasel_core/device.hpp"

#include <cmath>

namespace hasel {
namespace {

// long double literals: a build with -fsingle-precision-constant (Teensyduino's) would round
// unsuffixed ones to binary32, and the range check must be the host's, in double
constexpr double kSector = double(0.392699081698724154807830422909937861L);   // pi/8 [rad]
constexpr double kAngleSlack = double(1e-6L);   // section 6: float32(pi/8) > pi/8 by 4e-9

int32_t floor_div(int32_t a, int32_t b) {
  int32_t q = a / b;
  return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

int32_t mod(int32_t a, int32_t b) { return a - b * floor_div(a, b); }

bool is_host_type(uint8_t t) { return t >= kCommand && t <= kStart; }

}  // namespace

int32_t angle_counts(float phi) {
  float x = phi * kCountsPerRad;   // binary32 product (the build forbids contraction)
  int32_t c = int32_t(std::ceil(x));
  if (c > kCountsPerSector) c = kCountsPerSector;
  if (c < -kCountsPerSector) c = -kCountsPerSector;
  return c;
}

uint8_t check_command(uint8_t n_a, float phi_a, float phi_d) {
  if (n_a > 15) return kReasonNa;
  const float angles[2] = {phi_a, phi_d};
  for (float v : angles) {
    if (!std::isfinite(v) || std::fabs(double(v)) > kSector + kAngleSlack) return kReasonAngle;
  }
  if (!(phi_a < phi_d) || (phi_a < 0.0f && 0.0f < phi_d)) return kReasonOrder;
  return 0;
}

bool start_sector(uint8_t n_a, float phi_a, float phi_d, int32_t c, int32_t* sector) {
  // the window is at most 64 counts wide: only the largest N = n_a (mod 16) with
  // 64 N + a(phi_a) <= c can hold c
  int32_t top = floor_div(c - angle_counts(phi_a), kCountsPerSector);
  int32_t n = top - mod(top - int32_t(n_a), kPads);
  *sector = n;
  return c < n * kCountsPerSector + angle_counts(phi_d);
}

uint8_t check_config(const Message& m) {
  bool ok = m.telemetry_rate_hz >= 50 && m.telemetry_rate_hz <= 1000 && m.watchdog_ms >= 20 &&
            m.watchdog_ms <= 1000 && m.max_on_ms >= 10 && m.max_on_ms <= 10000 &&
            m.drain_mode == 0;
  return ok ? 0 : kReasonConfig;
}

void Device::reset() {
  s_ = DeviceState{};
  enc_.reset();
  decoder_.reset();
  rx_len_ = 0;
  now_us_ = 0;
  started_ = false;
}

size_t Device::receive(const uint8_t* data, size_t n) {
  size_t k = n < kRxBuffer - rx_len_ ? n : kRxBuffer - rx_len_;
  for (size_t i = 0; i < k; ++i) rx_[rx_len_++] = data[i];
  return k;
}

void Device::send(Message& m, FrameSink& sink) {
  s_.counter = uint16_t(s_.counter + 1);
  m.counter = s_.counter;
  uint8_t wire[kMaxWire];
  size_t n = encode(m, wire);
  sink.frame(wire, n);
}

void Device::pads_off() {
  s_.q = false;
  s_.target.valid = false;
  s_.pending.valid = false;
}

void Device::hv_off() {
  s_.hv_enabled = false;
  pads_off();
}

void Device::handle(const Message& m, FrameSink& sink) {
  s_.last_host_us = now_us_;
  Message reply;
  reply.type = kAck;
  reply.ref_type = m.type;
  reply.ref_counter = m.counter;
  reply.command_seq = (m.type == kCommand || m.type == kStart) ? m.command_seq : 0;
  uint8_t reason = 0;
  switch (m.type) {
    case kCommand:
    case kStart:
      reason = check_command(m.n_a, m.phi_a, m.phi_d);
      if (!reason && s_.estop) reason = kReasonEstop;
      if (!reason && !s_.hv_enabled) reason = kReasonHvDisabled;
      if (!reason && m.type == kStart) {
        reason = start(m);
      } else if (!reason) {
        s_.pending = Latched{true, m.command_seq, m.n_a, m.phi_a, m.phi_d, 0, 0, 0};
      }
      if (reason) {
        s_.faults |= kFaultRejected;
        break;
      }
      s_.faults &= ~uint32_t(kFaultRejected | kFaultMaxOn);
      break;
    case kHv:
      if (m.enable > 1) {
        reason = kReasonConfig;
      } else if (m.enable == 0) {
        hv_off();
      } else if (s_.estop) {
        reason = kReasonEstop;
      } else {
        if (!s_.hv_enabled) s_.hv_on_since_us = now_us_;
        s_.hv_enabled = true;
        s_.faults &= ~uint32_t(kFaultWatchdog | kFaultHvMonitor | kFaultOvercurrent);
      }
      break;
    case kEstop:
      hv_off();
      s_.estop = true;
      s_.faults |= kFaultEstop;
      break;
    case kClearEstop:
      s_.estop = false;
      s_.faults &= ~uint32_t(kFaultEstop);
      break;
    case kConfig:
      reason = check_config(m);
      if (!reason) {
        s_.telemetry_rate_hz = m.telemetry_rate_hz;
        s_.watchdog_ms = m.watchdog_ms;
        s_.max_on_ms = m.max_on_ms;
        s_.drain_mode = m.drain_mode;
      }
      break;
    default:  // HEARTBEAT: only restarts the watchdog
      break;
  }
  if (reason) {
    reply.type = kReject;
    reply.reason = reason;
  }
  send(reply, sink);
}

uint8_t Device::start(const Message& m) {
  // rule 8 past the checks it shares with COMMAND: pad n_a on now if it is in contact within
  // [phi_a, phi_d) on the last taken count; the pending command is cleared
  if (s_.q) return kReasonActuatorOn;
  int32_t c = enc_.unwrapped();
  int32_t n = 0;
  bool known = enc_.started() && enc_.bad_run() < kLostAfter;
  if (!known || !start_sector(m.n_a, m.phi_a, m.phi_d, c, &n)) return kReasonNotInContact;
  s_.pending.valid = false;
  s_.target = Latched{true, m.command_seq, m.n_a, m.phi_a, m.phi_d, n, c,
                      n * kCountsPerSector + angle_counts(m.phi_d), true};
  s_.eta_unwrapped = n;
  s_.last_command_seq = m.command_seq;
  s_.q = true;
  s_.on_since_us = now_us_;
  started_ = true;
  return 0;
}

void Device::interlocks(uint64_t now_us, const Sensors& sensors) {
  // rule 4: the watchdog
  if (s_.hv_enabled && now_us - s_.last_host_us >= uint64_t(s_.watchdog_ms) * 1000u) {
    hv_off();
    s_.faults |= kFaultWatchdog;
  }
  // rule 5: the maximum on-time
  if (s_.q && now_us - s_.on_since_us >= uint64_t(s_.max_on_ms) * 1000u) {
    pads_off();
    s_.faults |= kFaultMaxOn;
  }
  // section 6: the HV monitor and the supply current, each latched until HV is enabled again
  if (s_.hv_enabled) {
    if (!(sensors.current_monitor <= kCurrentLimitA)) {
      hv_off();
      s_.faults |= kFaultOvercurrent;
    } else if (now_us - s_.hv_on_since_us >= kHvSettleUs &&
               !(std::fabs(sensors.hv_monitor - kHvSetpointV) <= kHvBand * kHvSetpointV)) {
      hv_off();
      s_.faults |= kFaultHvMonitor;
    }
  }
}

void Device::latch(const Latched& u, int32_t count) {
  // rule 3: the first future switch-on of pad n_a, the smallest N = n_a (mod 16) with
  // 64 N + a >= count, where a is the activation angle in counts
  Latched t = u;
  int32_t a = angle_counts(u.phi_a);
  int32_t m = -floor_div(a - count, kCountsPerSector);          // ceil((count - a) / 64)
  t.sector = m + mod(int32_t(u.n_a) - m, kPads);
  t.on_count = t.sector * kCountsPerSector + a;
  t.off_count = t.sector * kCountsPerSector + angle_counts(u.phi_d);
  t.valid = true;
  s_.target = t;
  s_.eta_unwrapped = t.sector;
  s_.last_command_seq = t.seq;
}

void Device::switching(uint64_t now_us, const EncoderStep& reading) {
  int32_t c = reading.unwrapped;
  if (started_) return;                       // a START was this tick's one switch
  if (s_.q) {
    if (c >= s_.target.off_count) {           // switch off; latch what is pending
      s_.q = false;
      s_.target.valid = false;
      if (s_.pending.valid) {
        latch(s_.pending, c);
        s_.pending.valid = false;
      }
    }
    return;
  }
  if (s_.pending.valid) {                     // idle, or a target not yet on: latch now
    latch(s_.pending, c);
    s_.pending.valid = false;
  }
  if (s_.target.valid && s_.hv_enabled && c >= s_.target.on_count) {
    s_.q = true;
    s_.on_since_us = now_us;
  }
}

Outputs Device::outputs() const {
  Outputs o;
  o.hv_supply = s_.hv_enabled;
  o.active_mask = (s_.hv_enabled && s_.q) ? uint16_t(1u << mod(s_.eta_unwrapped, kPads)) : 0;
  o.telemetry_rate_hz = s_.telemetry_rate_hz;
  return o;
}

Outputs Device::tick(uint64_t now_us, const Sensors& sensors, FrameSink& sink) {
  now_us_ = now_us;
  started_ = false;
  Message m;
  for (size_t i = 0; i < rx_len_; ++i) {
    if (decoder_.push(rx_[i], &m) && is_host_type(m.type)) handle(m, sink);
  }
  rx_len_ = 0;
  interlocks(now_us, sensors);
  bool first = !enc_.started();
  EncoderStep reading = enc_.update(sensors.encoder_raw, sensors.encoder_ok);
  if (reading.good) {
    s_.faults &= ~uint32_t(kFaultEncoder);
    if (first) s_.eta_unwrapped = floor_div(reading.unwrapped, kCountsPerSector);
    switching(now_us, reading);
  } else {
    s_.faults |= kFaultEncoder;
    if (reading.lost) hv_off();
  }
  ++s_.sample_seq;
  Outputs o = outputs();
  Message t;
  t.type = kTelemetry;
  t.device_time_us = now_us;
  t.sample_seq = s_.sample_seq;
  t.encoder_raw = uint16_t(sensors.encoder_raw & 0x3FF);
  t.encoder_unwrapped = enc_.unwrapped();
  t.q = s_.q ? 1 : 0;
  t.eta = uint8_t(mod(s_.eta_unwrapped, kPads));
  t.eta_unwrapped = s_.eta_unwrapped;
  t.active_mask = o.active_mask;
  t.hv_monitor = sensors.hv_monitor;
  t.current_monitor = sensors.current_monitor;
  t.last_command_seq = s_.last_command_seq;
  t.fault_flags = s_.faults;
  send(t, sink);
  return o;
}

}  // namespace hasel
