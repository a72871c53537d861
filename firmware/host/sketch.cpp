// The Teensy sketch compiled as C++ for the host check (hasel_board_check), against the mock
// Arduino API in host/mock_arduino.
#include "hasel_wheel_fw.ino"
