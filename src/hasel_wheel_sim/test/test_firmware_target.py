"""The firmware core compiles for the Teensy 3.6 (Cortex-M4F) with Teensyduino's flags,
warnings as errors, and no float silently promoted to double (a software double on the M4).

Runs where ``arm-none-eabi-g++`` is installed (Debian: gcc-arm-none-eabi and
libstdc++-arm-none-eabi-newlib); with ``TEENSY_CORE_DIR`` set to PJRC's ``cores/teensy3``
it also compiles and links the whole sketch.  Elsewhere it skips and says why.
"""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from hasel_wheel_sim.device_cpp import FIRMWARE_DIR

CXX = shutil.which("arm-none-eabi-g++")
#: Teensyduino's flags for the Teensy 3.6 (boards.txt), and ours (firmware/platformio.ini).
TEENSY36 = ["-mthumb", "-mcpu=cortex-m4", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16",
            "-fsingle-precision-constant", "-Os", "-ffunction-sections", "-fdata-sections",
            "-std=gnu++17", "-fno-exceptions", "-fno-rtti", "-felide-constructors",
            "-ffp-contract=off", "-DF_CPU=180000000", "-D__MK66FX1M0__", "-DUSB_SERIAL",
            "-DLAYOUT_US_ENGLISH", "-DARDUINO=10813", "-DTEENSYDUINO=159"]
CORE = sorted((FIRMWARE_DIR / "core" / "src" / "hasel_core").glob("*.cpp"))

pytestmark = pytest.mark.skipif(CXX is None, reason="compiling for the Teensy 3.6 needs "
                                "arm-none-eabi-g++ (Debian: apt-get install gcc-arm-none-eabi "
                                "libstdc++-arm-none-eabi-newlib)")


@pytest.mark.parametrize("source", CORE, ids=lambda p: p.name)
def test_the_core_compiles_for_the_cortex_m4f_without_warnings(tmp_path, source):
    r = subprocess.run([CXX, *TEENSY36, "-Wall", "-Wextra", "-Wdouble-promotion", "-Werror",
                        "-I", str(FIRMWARE_DIR / "core" / "src"), "-c", str(source),
                        "-o", str(tmp_path / "out.o")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.mark.skipif(not os.environ.get("TEENSY_CORE_DIR"),
                    reason="set TEENSY_CORE_DIR to PJRC's cores/teensy3 to link the sketch")
def test_the_sketch_links_for_the_teensy_36(tmp_path):
    teensy3 = Path(os.environ["TEENSY_CORE_DIR"])
    sketch = FIRMWARE_DIR / "teensy" / "hasel_wheel_fw"
    main = tmp_path / "sketch.cpp"
    main.write_text("#include <Arduino.h>\n" + (sketch / "hasel_wheel_fw.ino").read_text())
    inc = ["-I", str(teensy3), "-I", str(FIRMWARE_DIR / "core" / "src"), "-I", str(sketch)]
    objs = []
    for src in [main, sketch / "board.cpp", *CORE, *teensy3.glob("*.c"), *teensy3.glob("*.cpp")]:
        obj = tmp_path / f"{len(objs)}.o"
        tool = CXX if src.suffix == ".cpp" else CXX.replace("g++", "gcc")
        flags = TEENSY36 if src.suffix == ".cpp" else [f for f in TEENSY36 if not f.startswith(
            ("-std", "-fno-rtti", "-felide"))]
        r = subprocess.run([tool, *flags, "-w", *inc, "-c", str(src), "-o", str(obj)],
                           capture_output=True, text=True)
        assert r.returncode == 0, f"{src}: {r.stderr[-2000:]}"
        objs.append(str(obj))
    elf = tmp_path / "wheel.elf"
    r = subprocess.run([CXX.replace("g++", "gcc"), "-Os", "-Wl,--gc-sections,--defsym=__rtc_localtime=0",
                        "--specs=nano.specs", *TEENSY36[:4], "-T", str(teensy3 / "mk66fx1m0.ld"),
                        "-o", str(elf), *objs, "-lstdc++", "-lm"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    size = subprocess.run([CXX.replace("g++", "size"), "-A", str(elf)], capture_output=True,
                          text=True, check=True).stdout
    text = sum(int(line.split()[1]) for line in size.splitlines()
               if line.startswith((".text", ".fini", ".ARM")))
    assert 0 < text < 1024 * 1024                     # the MK66FX1M0's 1 MB of flash
