// The firmware core as an Arduino library: Arduino CLI finds a library by a header directly in
// its src/ folder, so the sketch includes this one first.
#pragma once
#include "hasel_core/device.hpp"
#include "hasel_core/encoder.hpp"
#include "hasel_core/protocol.hpp"
