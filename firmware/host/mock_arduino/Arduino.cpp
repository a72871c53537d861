// The mock Arduino API and the simulated board behind it (see Arduino.h).
#include "Arduino.h"

#include <deque>

#include "pins.h"

namespace {

// EMS22A timing limits [ns]: CS low to the first CLK falling edge, CLK low and high phases,
// CS high between reads; DO is valid this long after a CLK rising edge.
constexpr uint64_t kEncSetupNs = 500;
constexpr uint64_t kEncPhaseNs = 500;
constexpr uint64_t kEncCsHighNs = 500;
constexpr uint64_t kEncDoValidNs = 375;
constexpr int kFrameBits = 16;

struct Pin {
  bool output = false;
  uint8_t latch = 0;    // output data register
  uint8_t pull = 0;     // INPUT, INPUT_PULLUP or INPUT_PULLDOWN
};

struct Tpic {           // one TPIC6C596: stage n of each register feeds DRAINn
  uint8_t shift = 0;
  uint8_t storage = 0;
};

struct Encoder {
  uint16_t frame = 0;
  bool connected = true;
  bool selected = false;
  int next_bit = 0;      // frame bits shifted out so far
  uint8_t out = 0;       // DO while selected
  bool first_fall = true;
  bool rose = false;     // a CLK rising edge in this read
  uint64_t t_cs_fall = 0, t_cs_rise = 0, t_clk_fall = 0, t_clk_rise = 0;
  bool cs_rose_once = false;
  uint32_t reads = 0;
  uint32_t timing_errors = 0;
};

struct Board {
  Pin pin[mock::kPins];
  Tpic u1, u2;           // U1 takes SER IN; U2 takes U1's SER OUT
  Encoder enc;
  int analog[mock::kPins] = {};
  unsigned analog_bits = 10;
  std::deque<uint8_t> rx;
  std::vector<uint8_t> tx;   // every byte written, for take_output
  int packet_fill = -1;      // bytes in the current packet; -1: none taken
  int queued = 0;            // packets waiting for the host
  bool host_stalled = false;
  uint32_t tx_overruns = 0;
  uint32_t flushes = 0;
  std::vector<mock::Event> events;
  mock::Snapshot begin;
};

Board sim;
uint64_t now = 0;        // [ns]; never reset

// The K66 watchdog: unlock (0xC520, 0xD928) opens a window for the configuration writes.
struct Watchdog {
  int unlock_step = 0;   // 2: unlocked
  bool enabled = false;
  uint32_t toval = 0;
  uint32_t presc = 0x400;
  int refresh_step = 0;
  uint32_t refreshes = 0;
  uint64_t last_refresh = 0;   // [ns]
};
Watchdog wdog;

int level_of(const Pin& p) {
  if (p.output) return p.latch;
  if (p.pull == INPUT_PULLUP) return 1;
  if (p.pull == INPUT_PULLDOWN) return 0;
  return -1;
}

void too_short(uint64_t since, uint64_t limit) {
  if (now - since < limit) ++sim.enc.timing_errors;
}

void tpic_edge(uint8_t pin, int to) {
  bool cleared = mock::level(pins::kTpicClr) == 0;
  if (pin == pins::kTpicClr && to == 0) sim.u1 = sim.u2 = Tpic{};
  if (cleared || to != 1) return;
  if (pin == pins::kTpicSrck) {
    uint8_t ser_out = uint8_t(sim.u1.shift >> 7);
    uint8_t ser_in = mock::level(pins::kTpicSerIn) == 1 ? 1 : 0;
    sim.u1.shift = uint8_t((sim.u1.shift << 1) | ser_in);
    sim.u2.shift = uint8_t((sim.u2.shift << 1) | ser_out);
  } else if (pin == pins::kTpicRck) {
    sim.u1.storage = sim.u1.shift;
    sim.u2.storage = sim.u2.shift;
  }
}

void encoder_cs(int to) {
  Encoder& e = sim.enc;
  if (to == 0 && !e.selected) {
    if (e.cs_rose_once) too_short(e.t_cs_rise, kEncCsHighNs);
    e.selected = true;
    e.next_bit = 0;
    e.out = 0;
    e.first_fall = true;
    e.rose = false;
    e.t_cs_fall = now;
  } else if (to == 1 && e.selected) {
    e.selected = false;
    if (e.next_bit == kFrameBits) ++e.reads;
    e.t_cs_rise = now;
    e.cs_rose_once = true;
  }
}

void encoder_clk(int to) {
  Encoder& e = sim.enc;
  if (!e.selected) return;
  if (to == 0) {
    too_short(e.first_fall ? e.t_cs_fall : e.t_clk_rise, e.first_fall ? kEncSetupNs : kEncPhaseNs);
    e.first_fall = false;
    e.t_clk_fall = now;
  } else if (to == 1) {
    too_short(e.t_clk_fall, kEncPhaseNs);
    e.t_clk_rise = now;
    e.rose = true;
    e.out = e.next_bit < kFrameBits ? uint8_t((e.frame >> (kFrameBits - 1 - e.next_bit)) & 1u) : 0;
    ++e.next_bit;
  }
}

// A pin's level may have changed: log it and let the parts see the edge.
void update(uint8_t pin, int before) {
  int after = mock::level(pin);
  if (after == before) return;
  sim.events.push_back({mock::Kind::kLevel, pin, int8_t(after)});
  tpic_edge(pin, after);
  if (pin == pins::kEncCs) encoder_cs(after);
  if (pin == pins::kEncClk) encoder_clk(after);
}

bool valid(uint8_t pin) { return pin < mock::kPins; }

}  // namespace

// -- Arduino API ------------------------------------------------------------------------------

void pinMode(uint8_t pin, uint8_t mode) {
  if (!valid(pin)) return;
  int before = mock::level(pin);
  Pin& p = sim.pin[pin];
  p.output = mode == OUTPUT;
  p.pull = p.output ? uint8_t(INPUT) : mode;
  update(pin, before);
}

void digitalWriteFast(uint8_t pin, uint8_t val) {
  if (!valid(pin)) return;
  int before = mock::level(pin);
  sim.pin[pin].latch = val ? 1 : 0;
  update(pin, before);
}

// Teensy 3.x: on an input, digitalWrite switches the pull-up instead of the output register.
void digitalWrite(uint8_t pin, uint8_t val) {
  if (!valid(pin)) return;
  if (sim.pin[pin].output) return digitalWriteFast(pin, val);
  pinMode(pin, val ? INPUT_PULLUP : INPUT);
}

uint8_t digitalRead(uint8_t pin) {
  if (!valid(pin)) return 0;
  const Encoder& e = sim.enc;
  if (pin == pins::kEncDo && e.selected && e.connected) {
    if (e.rose && now - e.t_clk_rise < kEncDoValidNs) ++sim.enc.timing_errors;
    return e.out;
  }
  return mock::level(pin) == 1 ? 1 : 0;
}

int analogRead(uint8_t pin) { return valid(pin) ? sim.analog[pin] : 0; }
void analogReadResolution(unsigned int bits) { sim.analog_bits = bits; }
void delayMicroseconds(uint32_t us) { now += uint64_t(us) * 1000u; }
uint32_t micros() { return uint32_t(now / 1000u); }
uint32_t millis() { return uint32_t(now / 1000000u); }

// -- USB serial -------------------------------------------------------------------------------

MockSerial Serial;

void MockSerial::begin(uint32_t) {
  mock::Snapshot& s = sim.begin;
  if (s.taken) return;
  s = {true, sim.events.size(), mock::storage(), mock::leds(), mock::level(pins::kHvEnable),
       mock::level(pins::kTpicG)};
  sim.events.push_back({mock::Kind::kSerialBegin, 0, 0});
}

int MockSerial::available() { return int(sim.rx.size()); }
int MockSerial::peek() { return sim.rx.empty() ? -1 : sim.rx.front(); }

int MockSerial::read() {
  if (sim.rx.empty()) return -1;
  int b = sim.rx.front();
  sim.rx.pop_front();
  return b;
}

size_t MockSerial::readBytes(char* buffer, size_t length) {
  size_t n = 0;
  while (n < length && !sim.rx.empty()) {
    buffer[n++] = char(sim.rx.front());
    sim.rx.pop_front();
  }
  return n;
}

// Teensy 3.x usb_serial_write_buffer_free(): the current packet's room, taking a fresh
// packet while fewer than the limit are queued.
int MockSerial::availableForWrite() {
  if (sim.packet_fill < 0) {
    if (sim.queued >= mock::kTxPacketLimit) return 0;
    sim.packet_fill = 0;
  }
  return mock::kTxPacket - sim.packet_fill;
}

size_t MockSerial::write(const uint8_t* data, size_t n) {
  sim.tx.insert(sim.tx.end(), data, data + n);
  for (size_t left = n; left > 0;) {
    if (sim.packet_fill < 0) {
      if (sim.queued >= mock::kTxPacketLimit) ++sim.tx_overruns;   // Teensy would wait here
      sim.packet_fill = 0;
    }
    size_t take = size_t(mock::kTxPacket - sim.packet_fill);
    if (take > left) take = left;
    sim.packet_fill += int(take);
    left -= take;
    if (sim.packet_fill == mock::kTxPacket) {
      ++sim.queued;
      sim.packet_fill = -1;
    }
  }
  return n;
}

size_t MockSerial::write(uint8_t b) { return write(&b, 1); }

void MockSerial::send_now() {
  ++sim.flushes;
  if (sim.packet_fill > 0) ++sim.queued;
  sim.packet_fill = -1;
}

// -- simulation control -----------------------------------------------------------------------

namespace mock {

void power_on() {
  wdog = Watchdog{};        // a reset leaves the watchdog as Teensyduino's start-up sets it
  Encoder enc;
  enc.frame = sim.enc.frame;
  enc.connected = sim.enc.connected;
  sim = Board{};
  sim.enc = enc;
  sim.u1 = {0xA5, 0x5A};    // power-up contents are undefined
  sim.u2 = {0x3C, 0xC3};
}

const std::vector<Event>& events() { return sim.events; }
int level(uint8_t pin) { return valid(pin) ? level_of(sim.pin[pin]) : -1; }
uint16_t storage() { return uint16_t(sim.u1.storage | (sim.u2.storage << 8)); }

// Actuator k: U1 DRAINk for k < 8, U2 DRAIN(k-8) for k >= 8; drains conduct only with G low.
uint16_t leds() {
  if (level(pins::kTpicG) != 0) return 0;
  uint16_t lit = 0;
  for (int k = 0; k < 16; ++k) {
    const Tpic& chip = k < 8 ? sim.u1 : sim.u2;
    if ((chip.storage >> (k % 8)) & 1u) lit = uint16_t(lit | (1u << k));
  }
  return lit;
}

const Snapshot& at_serial_begin() { return sim.begin; }

void set_encoder(uint16_t frame, bool connected) {
  sim.enc.frame = frame;
  sim.enc.connected = connected;
}

uint32_t encoder_reads() { return sim.enc.reads; }
uint32_t encoder_timing_errors() { return sim.enc.timing_errors; }

void set_analog(uint8_t pin, int counts) {
  if (valid(pin)) sim.analog[pin] = counts;
}

unsigned analog_bits() { return sim.analog_bits; }

void host_send(const uint8_t* data, size_t n) { sim.rx.insert(sim.rx.end(), data, data + n); }
size_t host_pending() { return sim.rx.size(); }
void set_host_stalled(bool stalled) { sim.host_stalled = stalled; }

std::vector<uint8_t> take_output() {
  std::vector<uint8_t> out;
  out.swap(sim.tx);
  if (!sim.host_stalled) sim.queued = 0;
  return out;
}

uint32_t tx_overruns() { return sim.tx_overruns; }
uint32_t flushes() { return sim.flushes; }
bool watchdog_enabled() { return wdog.enabled; }
uint32_t watchdog_timeout_ms() { return wdog.toval * ((wdog.presc >> 8) + 1); }
uint32_t watchdog_refreshes() { return wdog.refreshes; }
bool watchdog_expired() {
  return wdog.enabled && now - wdog.last_refresh > uint64_t(watchdog_timeout_ms()) * 1000000u;
}

void advance_us(uint64_t us) { now += us * 1000u; }
uint64_t now_ns() { return now; }

}  // namespace mock

void noInterrupts() {}
void interrupts() {}

MockWdogRegister WDOG_UNLOCK{0}, WDOG_STCTRLH{1}, WDOG_TOVALH{2}, WDOG_TOVALL{3}, WDOG_PRESC{4},
    WDOG_REFRESH{5};

MockWdogRegister& MockWdogRegister::operator=(uint32_t v) {
  switch (id) {
    case 0:
      wdog.unlock_step = (v == 0xC520) ? 1 : (v == 0xD928 && wdog.unlock_step == 1) ? 2 : 0;
      break;
    case 1:
      if (wdog.unlock_step == 2) {
        wdog.enabled = (v & WDOG_STCTRLH_WDOGEN) != 0;
        wdog.last_refresh = now;
      }
      break;
    case 2: if (wdog.unlock_step == 2) wdog.toval = (wdog.toval & 0xFFFFu) | (v << 16); break;
    case 3: if (wdog.unlock_step == 2) wdog.toval = (wdog.toval & 0xFFFF0000u) | (v & 0xFFFFu); break;
    case 4: if (wdog.unlock_step == 2) wdog.presc = v; break;
    default:
      if (v == 0xA602) {
        wdog.refresh_step = 1;
      } else if (v == 0xB480 && wdog.refresh_step == 1) {
        wdog.refresh_step = 0;
        ++wdog.refreshes;
        wdog.last_refresh = now;
      } else {
        wdog.refresh_step = 0;
      }
  }
  return *this;
}
