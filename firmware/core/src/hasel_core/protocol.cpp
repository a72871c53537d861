#include "hasel_core/protocol.hpp"

#include <cstring>

namespace hasel {
namespace {

// Little-endian writer and reader over a byte buffer (section 6: integers little-endian,
// floats IEEE-754 binary32 little-endian).
struct Writer {
  uint8_t* p;
  void u8(uint8_t v) { *p++ = v; }
  void u16(uint16_t v) { u8(uint8_t(v)); u8(uint8_t(v >> 8)); }
  void u32(uint32_t v) { u16(uint16_t(v)); u16(uint16_t(v >> 16)); }
  void u64(uint64_t v) { u32(uint32_t(v)); u32(uint32_t(v >> 32)); }
  void i32(int32_t v) { u32(uint32_t(v)); }
  void f32(float v) { uint32_t b; std::memcpy(&b, &v, 4); u32(b); }
};

struct Reader {
  const uint8_t* p;
  uint8_t u8() { return *p++; }
  uint16_t u16() { uint16_t lo = u8(); return uint16_t(lo | (uint16_t(u8()) << 8)); }
  uint32_t u32() { uint32_t lo = u16(); return lo | (uint32_t(u16()) << 16); }
  uint64_t u64() { uint64_t lo = u32(); return lo | (uint64_t(u32()) << 32); }
  int32_t i32() { return int32_t(u32()); }
  float f32() { uint32_t b = u32(); float v; std::memcpy(&v, &b, 4); return v; }
};

void pack_payload(const Message& m, Writer& w) {
  switch (m.type) {
    case kTelemetry:
      w.u64(m.device_time_us); w.u32(m.sample_seq); w.u16(m.encoder_raw);
      w.i32(m.encoder_unwrapped); w.u8(m.q); w.u8(m.eta); w.i32(m.eta_unwrapped);
      w.u16(m.active_mask); w.f32(m.hv_monitor); w.f32(m.current_monitor);
      w.u32(m.last_command_seq); w.u32(m.fault_flags);
      break;
    case kAck: w.u8(m.ref_type); w.u16(m.ref_counter); w.u32(m.command_seq); break;
    case kReject:
      w.u8(m.ref_type); w.u16(m.ref_counter); w.u32(m.command_seq); w.u8(m.reason);
      break;
    case kCommand:
    case kStart: w.u32(m.command_seq); w.u8(m.n_a); w.f32(m.phi_a); w.f32(m.phi_d); break;
    case kHeartbeat: w.u64(m.host_time_us); break;
    case kHv: w.u8(m.enable); break;
    case kConfig:
      w.u16(m.telemetry_rate_hz); w.u16(m.watchdog_ms); w.u16(m.max_on_ms);
      w.u8(m.drain_mode);
      break;
    default: break;  // ESTOP, CLEAR_ESTOP: no payload
  }
}

void unpack_payload(Reader& r, Message& m) {
  switch (m.type) {
    case kTelemetry:
      m.device_time_us = r.u64(); m.sample_seq = r.u32(); m.encoder_raw = r.u16();
      m.encoder_unwrapped = r.i32(); m.q = r.u8(); m.eta = r.u8(); m.eta_unwrapped = r.i32();
      m.active_mask = r.u16(); m.hv_monitor = r.f32(); m.current_monitor = r.f32();
      m.last_command_seq = r.u32(); m.fault_flags = r.u32();
      break;
    case kAck: m.ref_type = r.u8(); m.ref_counter = r.u16(); m.command_seq = r.u32(); break;
    case kReject:
      m.ref_type = r.u8(); m.ref_counter = r.u16(); m.command_seq = r.u32(); m.reason = r.u8();
      break;
    case kCommand:
    case kStart: m.command_seq = r.u32(); m.n_a = r.u8(); m.phi_a = r.f32(); m.phi_d = r.f32(); break;
    case kHeartbeat: m.host_time_us = r.u64(); break;
    case kHv: m.enable = r.u8(); break;
    case kConfig:
      m.telemetry_rate_hz = r.u16(); m.watchdog_ms = r.u16(); m.max_on_ms = r.u16();
      m.drain_mode = r.u8();
      break;
    default: break;
  }
}

}  // namespace

int payload_size(uint8_t type) {
  switch (type) {
    case kTelemetry: return 42;
    case kAck: return 7;
    case kReject: return 8;
    case kCommand:
    case kStart: return 13;
    case kHeartbeat: return 8;
    case kHv: return 1;
    case kEstop: return 0;
    case kConfig: return 7;
    case kClearEstop: return 0;
    default: return -1;
  }
}

namespace {

// CRC-16/CCITT-FALSE of every byte value, built at compile time (512 bytes of flash).
struct CrcTable {
  uint16_t v[256];
  constexpr CrcTable() : v() {
    for (int i = 0; i < 256; ++i) {
      uint16_t crc = uint16_t(i << 8);
      for (int b = 0; b < 8; ++b) crc = (crc & 0x8000) ? uint16_t((crc << 1) ^ 0x1021) : uint16_t(crc << 1);
      v[i] = crc;
    }
  }
};
constexpr CrcTable kCrcTable;

}  // namespace

uint16_t crc16(const uint8_t* data, size_t n) {
  uint16_t crc = 0xFFFF;
  for (size_t i = 0; i < n; ++i) crc = uint16_t((crc << 8) ^ kCrcTable.v[(crc >> 8) ^ data[i]]);
  return crc;
}

size_t cobs_encode(const uint8_t* in, size_t n, uint8_t* out) {
  size_t code_at = 0, o = 1;
  uint8_t code = 1;
  for (size_t i = 0; i < n; ++i) {
    if (in[i] == 0) {
      out[code_at] = code;
      code_at = o++;
      code = 1;
    } else {
      out[o++] = in[i];
      ++code;
    }
  }
  out[code_at] = code;
  return o;
}

int cobs_decode(const uint8_t* in, size_t n, uint8_t* out) {
  size_t i = 0, o = 0;
  while (i < n) {
    uint8_t code = in[i++];
    if (code == 0) return -1;
    size_t end = i + code - 1;
    if (end > n) return -1;
    while (i < end) {
      if (in[i] == 0) return -1;
      out[o++] = in[i++];
    }
    if (i < n && code < 0xFF) out[o++] = 0;
  }
  return int(o);
}

size_t encode(const Message& m, uint8_t* out) {
  int size = payload_size(m.type);
  if (size < 0) return 0;
  uint8_t raw[kMaxRaw];
  Writer w{raw};
  w.u8(kVersion);
  w.u8(m.type);
  w.u16(m.counter);
  pack_payload(m, w);
  size_t n = size_t(w.p - raw);
  w.u16(crc16(raw, n));
  size_t k = cobs_encode(raw, n + 2, out);
  out[k] = 0;
  return k + 1;
}

void Decoder::reset() {
  len_ = 0;
  discarding_ = false;
  stats_ = DecoderStats{};
}

bool Decoder::push(uint8_t byte, Message* out) {
  if (byte != 0) {
    if (discarding_) return false;
    if (len_ == kMaxStuffed) {  // a chunk over kMaxStuffed bytes: drop it whole
      ++stats_.oversize;
      len_ = 0;
      discarding_ = true;
      return false;
    }
    buf_[len_++] = byte;
    return false;
  }
  if (discarding_) {
    discarding_ = false;
    return false;
  }
  if (len_ == 0) return false;  // an empty chunk (two delimiters in a row)
  bool ok = finish(out);
  len_ = 0;
  return ok;
}

bool Decoder::finish(Message* out) {
  uint8_t raw[kMaxStuffed];
  int n = cobs_decode(buf_, len_, raw);
  if (n < int(kHeader + 2)) {
    ++stats_.framing_errors;
    return false;
  }
  uint16_t crc = uint16_t(raw[n - 2] | (raw[n - 1] << 8));
  if (crc16(raw, size_t(n - 2)) != crc) {
    ++stats_.crc_errors;
    return false;
  }
  if (raw[0] != kVersion) {
    ++stats_.version_errors;
    return false;
  }
  int size = payload_size(raw[1]);
  if (size < 0) {
    ++stats_.type_errors;
    return false;
  }
  if (n - int(kHeader) - 2 != size) {
    ++stats_.length_errors;
    return false;
  }
  Message m;
  m.type = raw[1];
  m.counter = uint16_t(raw[2] | (raw[3] << 8));
  Reader r{raw + kHeader};
  unpack_payload(r, m);
  *out = m;
  ++stats_.frames;
  return true;
}

}  // namespace hasel
