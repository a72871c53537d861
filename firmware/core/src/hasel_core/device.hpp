// The device rules of protocol v1.1 section 4 on the device's own readings: what the Teensy
// decides on every tick.  Portable C++17, no allocation, no Arduino headers; the board layer
// (firmware/teensy) feeds it bytes and sensor readings and applies its outputs.
#pragma once
#include <cstddef>
#include <cstdint>

#include "hasel_core/encoder.hpp"
#include "hasel_core/protocol.hpp"

namespace hasel {

// Limits of the device's own checks (protocol section 6, fault bits 2 and 4).
constexpr float kHvSetpointV = 9000.0f;      // HV converter output while enabled [V]
constexpr float kHvBand = 0.10f;             // allowed deviation from the set point [1]
constexpr uint32_t kHvSettleUs = 100000;     // HV monitor ignored this long after enabling [us]
constexpr float kCurrentLimitA = 2.0e-3f;    // supply current limit (converter: 3 mA max) [A]
// One encoder count is 2 pi / 1024 rad; 512 / pi counts per rad, as binary32.
constexpr float kCountsPerRad = 162.974661726101f;
constexpr int32_t kCountsPerSector = 64;     // pi/8 rad
constexpr int32_t kPads = 16;

// What the board reads at the start of a tick.
struct Sensors {
  uint16_t encoder_raw = 0;      // 0..1023
  bool encoder_ok = true;        // false: the encoder's read failed (parity, status bits)
  float hv_monitor = 0.0f;       // [V]
  float current_monitor = 0.0f;  // [A]
};

// What the board applies until the next tick.
struct Outputs {
  uint16_t active_mask = 0;      // bit i: actuator i gets HV (at most one bit)
  bool hv_supply = false;        // the HV converter's 24 V supply
  uint16_t telemetry_rate_hz = 300;  // tick rate from the next tick on
};

// The command the device latched (its target pad) or holds pending.
struct Latched {
  bool valid = false;
  uint32_t seq = 0;
  uint8_t n_a = 0;
  float phi_a = 0.0f;            // [rad], as received (within the protocol's slack)
  float phi_d = 0.0f;            // [rad]
  int32_t sector = 0;            // unwrapped sector N of the target pad
  int32_t on_count = 0;          // switch on when the unwrapped count reaches this (a START:
                                 // the count it switched on at)
  int32_t off_count = 0;         // switch off when it reaches this
  bool now = false;              // a START latched it (rule 8), switching the pad on at once
};

// Everything the device state holds, for tests and the lockstep comparison.
struct DeviceState {
  bool hv_enabled = false;
  bool estop = false;
  uint32_t faults = 0;
  uint16_t counter = 0;           // counter of the last frame sent
  uint32_t sample_seq = 0;
  uint64_t last_host_us = 0;      // time of the tick that handled the last valid host frame
  uint64_t hv_on_since_us = 0;
  uint64_t on_since_us = 0;       // switch-on time of the pad that is on
  bool q = false;                 // a pad is on
  int32_t eta_unwrapped = 0;      // the actuator of interest's unwrapped sector
  uint32_t last_command_seq = 0;
  Latched pending;
  Latched target;                 // valid = armed (a target latched)
  uint16_t telemetry_rate_hz = 300;
  uint16_t watchdog_ms = 100;
  uint16_t max_on_ms = 2000;
  uint8_t drain_mode = 0;
};

// Receives the device's outgoing frames, whole (the board drops a frame it has no room for).
class FrameSink {
 public:
  virtual void frame(const uint8_t* wire, size_t n) = 0;

 protected:
  ~FrameSink() = default;
};

// Smallest count c with c >= phi * 512/pi (phi in rad), computed in binary32 as the protocol
// prescribes, limited to one sector either way.
int32_t angle_counts(float phi);

// 0 if u = (n_a, phi_a, phi_d) is acceptable, else its REJECT reason (protocol rule 7); the
// value check of COMMAND and START alike.
uint8_t check_command(uint8_t n_a, float phi_a, float phi_d);

// Rule 8 in counts (section 6): true when pad n_a is in contact within [phi_a, phi_d) [rad] at
// the unwrapped count c, with *sector the N = n_a (mod 16) for which
// 64 N + a(phi_a) <= c < 64 N + a(phi_d).
bool start_sector(uint8_t n_a, float phi_a, float phi_d, int32_t c, int32_t* sector);

// 0 if the configuration is acceptable, else kReasonConfig (protocol rule 7).
uint8_t check_config(const Message& m);

class Device {
 public:
  Device() { reset(); }

  // Power-up state (rule 1): HV off, nothing latched, estop clear, default configuration.
  void reset();

  // Take host bytes as they arrive, as many as the receive buffer has room for; frames are
  // handled at the next tick, in arrival order.  Returns how many were taken: the board leaves
  // the rest in its USB buffers for the next call.
  size_t receive(const uint8_t* data, size_t n);
  // Bytes receive() takes now.
  size_t rx_room() const { return kRxBuffer - rx_len_; }

  // One tick at device time now_us: host frames (each answered), rules 4-6, the encoder
  // reading and at most one switch, then one TELEMETRY frame.  Frames go to `sink`.
  Outputs tick(uint64_t now_us, const Sensors& sensors, FrameSink& sink);

  const DeviceState& state() const { return s_; }
  const EncoderTrack& encoder() const { return enc_; }
  const DecoderStats& decoder_stats() const { return decoder_.stats(); }

 private:
  void handle(const Message& m, FrameSink& sink);
  void send(Message& m, FrameSink& sink);
  void hv_off();
  void pads_off();
  void latch(const Latched& u, int32_t count);
  uint8_t start(const Message& m);
  void interlocks(uint64_t now_us, const Sensors& sensors);
  void switching(uint64_t now_us, const EncoderStep& reading);
  Outputs outputs() const;

  static constexpr size_t kRxBuffer = 512;
  DeviceState s_;
  EncoderTrack enc_;
  Decoder decoder_;
  uint8_t rx_[kRxBuffer] = {};
  size_t rx_len_ = 0;
  uint64_t now_us_ = 0;
  bool started_ = false;  // a START switched a pad on at this tick (its one switch)
};

}  // namespace hasel
