// Runs the core's tick N times on a rolling wheel with a command, a heartbeat and telemetry in
// every tick, so that `valgrind --tool=callgrind` can count the instructions one tick costs
// (benchmarks/bench_firmware_tick.py).  Usage: hasel_tick_bench TICKS
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "hasel_core/device.hpp"

namespace {

struct CountingSink final : hasel::FrameSink {
  size_t bytes = 0;
  void frame(const uint8_t*, size_t n) override { bytes += n; }
};

size_t host_frame(hasel::Message m, uint16_t counter, uint8_t* out) {
  m.counter = counter;
  return hasel::encode(m, out);
}

}  // namespace

int main(int argc, char** argv) {
  long ticks = argc > 1 ? std::atol(argv[1]) : 0;
  hasel::Device dev;
  CountingSink sink;
  uint8_t wire[hasel::kMaxWire];
  uint16_t counter = 0;
  hasel::Message hv;
  hv.type = hasel::kHv;
  hv.enable = 1;
  size_t n = host_frame(hv, ++counter, wire);
  dev.receive(wire, n);
  uint64_t now = 0;
  hasel::Sensors s;
  s.hv_monitor = 9000.0f;
  s.current_monitor = 3e-4f;
  for (long k = 0; k < ticks; ++k) {
    now += 3333;
    // every tick: a heartbeat and a command (the host's worst case), 6 counts of travel
    hasel::Message hb;
    hb.type = hasel::kHeartbeat;
    hb.host_time_us = now;
    n = host_frame(hb, ++counter, wire);
    dev.receive(wire, n);
    hasel::Message cmd;
    cmd.type = hasel::kCommand;
    cmd.command_seq = uint32_t(k + 1);
    cmd.n_a = uint8_t((k / 10 + 1) % 16);
    cmd.phi_a = 0.05f;
    cmd.phi_d = 0.38f;
    n = host_frame(cmd, ++counter, wire);
    dev.receive(wire, n);
    s.encoder_raw = uint16_t((k * 6) % 1024);
    dev.tick(now, s, sink);
  }
  std::printf("%ld ticks, %zu bytes sent\n", ticks, sink.bytes);
  return 0;
}
