// A minimal Arduino API on the host, with the wheel's board simulated behind it, so the
// Teensyduino layer (firmware/teensy) compiles with the system compiler and can be checked
// (host/board_check.cpp).  Teensy 3.x semantics where they matter: digitalWriteFast sets the
// output register even while the pin is an input, pinMode(OUTPUT) then drives that level,
// micros() is 32 bits and wraps.  Time is simulated: only delayMicroseconds and
// mock::advance_us move it.  Not part of the Teensy build.
#pragma once
#include <stddef.h>
#include <stdint.h>

#include <vector>

#define LOW 0
#define HIGH 1
#define INPUT 0
#define OUTPUT 1
#define INPUT_PULLUP 2
#define INPUT_PULLDOWN 3

constexpr uint8_t A0 = 14;   // Teensy 3.6 analog pins A0, A1 are digital pins 14, 15
constexpr uint8_t A1 = 15;

void pinMode(uint8_t pin, uint8_t mode);
void digitalWrite(uint8_t pin, uint8_t val);
void digitalWriteFast(uint8_t pin, uint8_t val);
uint8_t digitalRead(uint8_t pin);
int analogRead(uint8_t pin);
void analogReadResolution(unsigned int bits);
void delayMicroseconds(uint32_t us);
void noInterrupts();
void interrupts();

// The Teensy 3.6's watchdog (Kinetis K66 WDOG), as kinetis.h names it: writes go to the
// simulated watchdog (mock::watchdog_*).
struct MockWdogRegister {
  uint8_t id;
  MockWdogRegister& operator=(uint32_t value);
};
extern MockWdogRegister WDOG_UNLOCK, WDOG_STCTRLH, WDOG_TOVALH, WDOG_TOVALL, WDOG_PRESC,
    WDOG_REFRESH;
#define WDOG_UNLOCK_SEQ1 ((uint16_t)0xC520)
#define WDOG_UNLOCK_SEQ2 ((uint16_t)0xD928)
#define WDOG_STCTRLH_WDOGEN ((uint16_t)0x0001)
#define WDOG_STCTRLH_ALLOWUPDATE ((uint16_t)0x0010)
#define WDOG_STCTRLH_STOPEN ((uint16_t)0x0040)
#define WDOG_STCTRLH_WAITEN ((uint16_t)0x0080)
uint32_t micros();
uint32_t millis();

// USB serial (Teensy's usb_serial_class, the members the sketch uses).
class MockSerial {
 public:
  void begin(uint32_t baud);
  int available();
  int peek();
  int read();
  size_t readBytes(char* buffer, size_t length);
  int availableForWrite();
  size_t write(const uint8_t* data, size_t n);
  size_t write(uint8_t b);
  void send_now();
};
extern MockSerial Serial;

// The simulated board, wired as firmware/teensy/hasel_wheel_fw/pins.h says: two daisy-chained
// TPIC6C596 driving the 16 optocoupler LEDs, an EMS22A encoder, the HV supply's EN, two analog
// monitors and the USB host.
namespace mock {

constexpr int kPins = 64;

enum class Kind : uint8_t { kLevel, kSerialBegin };
// kLevel: `pin` changed its level to `level` (0, 1, or -1: floating input).
struct Event {
  Kind kind;
  uint8_t pin;
  int8_t level;
};

// Power-up: every pin an input without pull, garbage in the shift registers, serial empty,
// the event log cleared.  Time keeps running (micros() never jumps back).
void power_on();

const std::vector<Event>& events();
int level(uint8_t pin);        // 0, 1, or -1 (floating input)
uint16_t storage();            // the storage registers: bit k feeds actuator k's LED
uint16_t leds();               // bit k: actuator k's optocoupler LED is lit

// The board as it was when Serial.begin was called.
struct Snapshot {
  bool taken = false;
  size_t events = 0;           // events logged before it
  uint16_t storage = 0;
  uint16_t leds = 0;
  int hv_enable = -1;          // level of the HV supply's EN
  int g = -1;                  // level of the TPIC6C596 G line
};
const Snapshot& at_serial_begin();

// The EMS22A serves `frame` (16 bits, MSB first) on every read; a disconnected one never
// drives DO.
void set_encoder(uint16_t frame, bool connected = true);
uint32_t encoder_reads();           // complete 16-bit reads
uint32_t encoder_timing_errors();   // EMS22A timing violations seen

void set_analog(uint8_t pin, int counts);
unsigned analog_bits();             // resolution the sketch set

void host_send(const uint8_t* data, size_t n);   // bytes from the host to the device
size_t host_pending();                           // of them, not yet read by the sketch

// Transmit side as on Teensy 3.x: 64-byte packets, at most kTxPacketLimit queued for the
// host.  availableForWrite() is the room left in the current packet (a fresh one is taken
// while the queue has space, else 0); a full packet or send_now() queues the current one.
constexpr int kTxPacket = 64;
constexpr int kTxPacketLimit = 8;
std::vector<uint8_t> take_output();   // bytes the device wrote since the last call; the host
                                      // reads the queued packets unless it stalls
void set_host_stalled(bool stalled);  // a stalled host reads nothing: the queue fills up
uint32_t tx_overruns();               // writes that would have waited for a packet
uint32_t flushes();                   // Serial.send_now() calls

// The watchdog: enabled by an unlocked STCTRLH write with WDOGEN, timeout TOVAL ms of the
// 1 kHz LPO clock (PRESC 0), restarted by the refresh pair 0xA602, 0xB480.
bool watchdog_enabled();
uint32_t watchdog_timeout_ms();
uint32_t watchdog_refreshes();
bool watchdog_expired();              // enabled, and not refreshed for longer than the timeout

void advance_us(uint64_t us);
uint64_t now_ns();

}  // namespace mock
