// Codec of the wheel's serial protocol v1.1 (docs/protocol.md sections 1-3): CRC-16/CCITT-FALSE,
// COBS framing, the message layouts, and an incremental decoder that never fails on input
// bytes.  Portable C++17, no allocation, no Arduino headers.
#pragma once
#include <cstddef>
#include <cstdint>

namespace hasel {

constexpr uint8_t kVersion = 1;                // v1.1 adds START, not a version byte
constexpr size_t kMaxRaw = 64;                 // raw frame bytes: header + payload + CRC
constexpr size_t kMaxStuffed = kMaxRaw + 2;    // COBS adds one byte per 254, plus one
constexpr size_t kMaxWire = kMaxStuffed + 1;   // with the 0x00 delimiter
constexpr size_t kHeader = 4;                  // version, type, counter (u16)

enum Type : uint8_t {
  kTelemetry = 0x01, kAck = 0x02, kReject = 0x03,
  kCommand = 0x10, kHeartbeat = 0x11, kHv = 0x12, kEstop = 0x13, kConfig = 0x14,
  kClearEstop = 0x15,
  kStart = 0x16,  // v1.1: switch the pad in contact on now (rule 8)
};

enum Reason : uint8_t {
  kReasonNa = 1, kReasonAngle = 2, kReasonOrder = 3, kReasonHvDisabled = 4, kReasonEstop = 5,
  kReasonConfig = 6,
  kReasonNotInContact = 7,  // v1.1 START: pad n_a not within [phi_a, phi_d), or position lost
  kReasonActuatorOn = 8,    // v1.1 START: an actuator is on
};

enum Fault : uint32_t {
  kFaultWatchdog = 1, kFaultHvMonitor = 2, kFaultOvercurrent = 4, kFaultMaxOn = 8,
  kFaultEncoder = 16, kFaultRejected = 32, kFaultEstop = 64,
};

// One message of any type: the fields of section 3 side by side; only those of `type` are
// meaningful.  ACK and REJECT name the frame they answer in ref_type / ref_counter.
struct Message {
  uint8_t type = 0;
  uint16_t counter = 0;
  // TELEMETRY
  uint64_t device_time_us = 0;
  uint32_t sample_seq = 0;
  uint16_t encoder_raw = 0;
  int32_t encoder_unwrapped = 0;
  uint8_t q = 0;
  uint8_t eta = 0;
  int32_t eta_unwrapped = 0;
  uint16_t active_mask = 0;
  float hv_monitor = 0.0f;        // [V]
  float current_monitor = 0.0f;   // [A]
  uint32_t last_command_seq = 0;
  uint32_t fault_flags = 0;
  // ACK, REJECT
  uint8_t ref_type = 0;
  uint16_t ref_counter = 0;
  uint32_t command_seq = 0;       // also COMMAND's and START's
  uint8_t reason = 0;
  // COMMAND, START
  uint8_t n_a = 0;
  float phi_a = 0.0f;             // [rad]
  float phi_d = 0.0f;             // [rad]
  // HEARTBEAT, HV, CONFIG
  uint64_t host_time_us = 0;
  uint8_t enable = 0;
  uint16_t telemetry_rate_hz = 0;
  uint16_t watchdog_ms = 0;
  uint16_t max_on_ms = 0;
  uint8_t drain_mode = 0;
};

// Payload size of a message type, or -1 for a type protocol v1.1 does not define.
int payload_size(uint8_t type);

// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF); its check value for "123456789" is 0x29B1.
uint16_t crc16(const uint8_t* data, size_t n);

// COBS-encode n bytes (n <= 254) into out; returns the stuffed length (n + 1).
size_t cobs_encode(const uint8_t* in, size_t n, uint8_t* out);
// COBS-decode n stuffed bytes (no 0x00 among them) into out (room for n bytes); returns the
// decoded length, or -1 when a code byte points past the end.
int cobs_decode(const uint8_t* in, size_t n, uint8_t* out);

// The wire bytes of one frame, COBS(raw frame) + 0x00, into out (room for kMaxWire bytes);
// returns their number, or 0 for a type protocol v1.1 does not define.
size_t encode(const Message& m, uint8_t* out);

// What a decoder dropped, by cause (section 1), and what it delivered.
struct DecoderStats {
  uint32_t frames = 0;
  uint32_t crc_errors = 0;
  uint32_t framing_errors = 0;
  uint32_t oversize = 0;
  uint32_t version_errors = 0;
  uint32_t type_errors = 0;
  uint32_t length_errors = 0;
};

// Incremental decoder: push() bytes in any chunking; a complete valid frame is returned at its
// delimiter.  Resynchronises at the next 0x00 after any damage and counts every drop.
class Decoder {
 public:
  // Take one byte; true when it completed a valid frame, then written to *out.
  bool push(uint8_t byte, Message* out);
  const DecoderStats& stats() const { return stats_; }
  void reset();

 private:
  bool finish(Message* out);
  uint8_t buf_[kMaxStuffed] = {};
  size_t len_ = 0;
  bool discarding_ = false;
  DecoderStats stats_;
};

}  // namespace hasel
