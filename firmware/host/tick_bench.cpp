// Runs the core's tick on a rolling wheel so that `valgrind --tool=callgrind` can count the
// instructions one tick costs (benchmarks/bench_firmware.py).
//   hasel_tick_bench TICKS typical    a heartbeat every 6th tick and a command every 20th
//   hasel_tick_bench TICKS commands   the receive buffer full of commands at every tick
//   hasel_tick_bench TICKS starts     the receive buffer full of STARTs for a pad not in
//                                     contact at every tick: each goes through every check
//   hasel_tick_bench TICKS answers    the receive buffer full of the smallest frames (8 bytes,
//                                     CLEAR_ESTOP) at every tick: the most answers per tick
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "hasel_core/device.hpp"

namespace {

struct CountingSink final : hasel::FrameSink {
  size_t bytes = 0;
  void frame(const uint8_t*, size_t n) override { bytes += n; }
};

struct Host {
  hasel::Device& dev;
  uint16_t counter = 0;
  // queue one frame; false when the receive buffer had no room for all of it
  bool send(hasel::Message m) {
    uint8_t wire[hasel::kMaxWire];
    m.counter = ++counter;
    size_t n = hasel::encode(m, wire);
    return dev.receive(wire, n) == n;
  }
};

hasel::Message command(long k) {
  hasel::Message c;
  c.type = hasel::kCommand;
  c.command_seq = uint32_t(k + 1);
  c.n_a = uint8_t((k / 10 + 1) % 16);
  c.phi_a = 0.05f;
  c.phi_d = 0.38f;
  return c;
}

// A START for the pad half a turn from the one in contact at count c: REJECTed (reason 7)
// after every check of rule 8.
hasel::Message start(long k, long c) {
  hasel::Message m = command(k);
  m.type = hasel::kStart;
  m.n_a = uint8_t((c / 64 + 8) % 16);
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  long ticks = argc > 1 ? std::atol(argv[1]) : 0;
  const char* mode = argc > 2 ? argv[2] : "typical";
  bool commands = std::strcmp(mode, "commands") == 0;
  bool starts = std::strcmp(mode, "starts") == 0;
  bool answers = std::strcmp(mode, "answers") == 0;
  hasel::Message clear;
  clear.type = hasel::kClearEstop;
  hasel::Device dev;
  Host host{dev};
  CountingSink sink;
  hasel::Message hv;
  hv.type = hasel::kHv;
  hv.enable = 1;
  host.send(hv);
  hasel::Sensors s;
  s.hv_monitor = 9000.0f;
  s.current_monitor = 3e-4f;
  uint64_t now = 0;
  for (long k = 0; k < ticks; ++k) {
    now += 3333;
    if (commands) {
      while (host.send(command(k))) {
      }
    } else if (starts) {
      while (host.send(start(k, (k * 3) % 1024))) {
      }
    } else if (answers) {
      while (host.send(clear)) {
      }
    } else {
      if (k % 6 == 0) {
        hasel::Message hb;
        hb.type = hasel::kHeartbeat;
        hb.host_time_us = now;
        host.send(hb);
      }
      if (k % 20 == 0) host.send(command(k));
    }
    s.encoder_raw = uint16_t((k * 3) % 1024);   // 1.8 rad/s
    dev.tick(now, s, sink);
  }
  std::printf("%ld ticks, %zu bytes sent\n", ticks, sink.bytes);
  return 0;
}
