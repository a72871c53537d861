// Every Teensy 3.6 pin the wheel firmware uses, with its wiring on the wheel's PCB, and the
// scales of the two analog monitors.  Teensy 3.6 I/O runs at 3.3 V and is NOT 5 V tolerant.
#pragma once
#include <Arduino.h>
#include <stdint.h>

namespace pins {

// -- Optocoupler LED drivers: two TPIC6C596 power shift registers, U1 and U2, daisy-chained:
//    U1 pin 9 (SER OUT) -> U2 pin 2 (SER IN).  SRCK, RCK, CLR and G go to both chips.
//    TPIC6C596 pins: 1 VCC, 2 SER IN, 3-6 DRAIN0-3, 7 CLR, 8 G, 9 SER OUT, 10 RCK,
//    11-14 DRAIN4-7, 15 SRCK, 16 GND.
//    Actuator k (0..15) is the OZ100SG optocoupler whose IR LED is sunk by
//    U1 DRAINk for k < 8 and by U2 DRAIN(k-8) for k >= 8.  A 1 bit lights the LED.
//    Board requirement: a pull-up on G keeps every drain off while the Teensy is in reset.
constexpr uint8_t kTpicSerIn = 2;  // -> U1 pin 2 SER IN (serial data)
constexpr uint8_t kTpicSrck = 3;   // -> U1, U2 pin 15 SRCK (shift on the rising edge)
constexpr uint8_t kTpicRck = 4;    // -> U1, U2 pin 10 RCK (latch to the outputs, rising edge)
constexpr uint8_t kTpicClr = 5;    // -> U1, U2 pin 7 CLR (low: every register cleared)
constexpr uint8_t kTpicG = 6;      // -> U1, U2 pin 8 G (high: every drain off)

// -- EMS22A50 absolute encoder, 10 bits, synchronous serial.  EMS22A pins: 1 DI (daisy-chain
//    input, unused), 2 CLK, 3 GND, 4 DO, 5 VCC (5 V for the A50), 6 CS.
//    Board requirement: DO is 5 V logic and must reach the Teensy through a level shifter.
constexpr uint8_t kEncCs = 7;      // -> EMS22A pin 6 CS (low: selected)
constexpr uint8_t kEncClk = 8;     // -> EMS22A pin 2 CLK (idles high)
constexpr uint8_t kEncDo = 9;      // <- EMS22A pin 4 DO (via level shifter)

// -- HV converter supply: Pololu U3V50F24 step-up (24 V) feeding the Advanced Energy 10A24-P30.
//    Board requirement: a pull-down on EN if the module pulls EN up, so 24 V stays off in reset.
constexpr uint8_t kHvEnable = 10;  // -> U3V50F24 EN (high: 24 V on, so HV on)

// -- Monitors through the TLV4172 op-amp stage, 0..3.3 V at the Teensy.
constexpr uint8_t kHvMonitor = A0;       // pin 14 <- TLV4172 output, HV monitor
constexpr uint8_t kCurrentMonitor = A1;  // pin 15 <- TLV4172 output, current monitor

// -- ADC scaling.  The ADC reads 12 bits (0..4095 over 0..3.3 V).
constexpr uint8_t kAdcBits = 12;
// BOARD CALIBRATION VALUES: MEASURE THEM ON YOUR BOARD before relying on fault bits 2 and 4.
// The values below are placeholders (10 kV and 3 mA full scale at 3.3 V), not measurements.
// Measure: HV monitor counts against a HV probe at two voltages; current monitor counts
// against a series ammeter; enter the slope.
constexpr float kHvVoltsPerCount = 10000.0f / 4095.0f;      // [V / count]   PLACEHOLDER
constexpr float kCurrentAmpsPerCount = 3.0e-3f / 4095.0f;   // [A / count]   PLACEHOLDER

}  // namespace pins
