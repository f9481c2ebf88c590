"""firmware/: the C codec, compiled with the system C compiler, against the Python codec.

The C sources are built into a temporary folder with ``cc -std=c99 -Wall -Wextra -Werror
-pedantic``; the host unit test must print OK, and ``crosscheck`` (a stdin/stdout driver)
must agree with ``bridge.protocol.robust`` byte for byte: CRCs, COBS, encoded frames, and the
frames and statistics decoded from streams with garbage, cut, corrupted, oversized and
mismatched-version frames, in both directions.
"""

from __future__ import annotations

import os
import random
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.mcu import EmulatedMCU
from bridge.protocol import (
    Feedback,
    Hello,
    Message,
    RobustDecoder,
    WheelCommand,
    crc16_ccitt_false,
    encode_frame,
    encode_message,
    pack_message,
)

FIRMWARE = Path(__file__).resolve().parents[2] / "firmware"
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]


def _compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.fail(
            "no C compiler found (looked for $CC, cc, gcc): the firmware tests compile "
            "firmware/*.c and must not be skipped; install one (e.g. apt-get install gcc)"
        )
    return cc


def _build(out_dir: Path, main: str, extra: list[str] | None = None) -> Path:
    exe = out_dir / Path(main).stem
    cmd = [
        _compiler(),
        *CFLAGS,
        *(extra or []),
        "-I",
        str(FIRMWARE),
        str(FIRMWARE / "pf_link.c"),
        str(FIRMWARE / "test" / main),
        "-o",
        str(exe),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert result.returncode == 0, f"{' '.join(cmd)}\n{result.stdout}{result.stderr}"
    return exe


class CrossCheck:
    """The crosscheck driver as a process: one command in, its answer lines out."""

    def __init__(self, exe: Path) -> None:
        self.proc = subprocess.Popen(
            [str(exe)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1
        )

    def ask(self, line: str) -> list[str]:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        answer = []
        while (got := self.proc.stdout.readline()) != ".\n":
            assert got, "crosscheck exited"
            answer.append(got.rstrip("\n"))
        return answer

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=10)


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("firmware")


@pytest.fixture(scope="module")
def crosscheck(build_dir: Path) -> Iterator[CrossCheck]:
    driver = CrossCheck(_build(build_dir, "crosscheck.c"))
    yield driver
    driver.close()


def hexs(data: bytes) -> str:
    return data.hex() or "-"


def wire_of(answer: list[str]) -> bytes:
    (line,) = answer
    tag, data = line.split(" ")
    assert tag == "W"
    return b"" if data == "-" else bytes.fromhex(data)


# ---- the host unit test --------------------------------------------------------------------


def test_host_unit_test_passes(build_dir: Path) -> None:
    result = subprocess.run(
        [str(_build(build_dir, "host_test.c"))], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout == "OK\n"


def test_host_unit_test_passes_under_undefined_behaviour_sanitizer(build_dir: Path) -> None:
    probe = subprocess.run(
        [_compiler(), "-fsanitize=undefined", "-x", "c", "-", "-o", str(build_dir / "probe")],
        input="int main(void) { return 0; }\n",
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode != 0:
        pytest.skip(f"this compiler cannot link -fsanitize=undefined: {probe.stderr.strip()}")
    ub_dir = build_dir / "ubsan"
    ub_dir.mkdir(exist_ok=True)
    exe = _build(ub_dir, "host_test.c", ["-fsanitize=undefined", "-fno-sanitize-recover=all"])
    result = subprocess.run([str(exe)], capture_output=True, text=True, check=False)
    assert (result.returncode, result.stdout) == (0, "OK\n"), result.stderr


# ---- building blocks: CRC and COBS ----------------------------------------------------------


def _random_bytes(rng: random.Random, n: int) -> bytes:
    """Random bytes, zero-rich half the time (COBS's interesting inputs)."""
    if rng.random() < 0.5:
        return bytes(rng.choice((0, 0, 1, 0xFF, rng.randrange(256))) for _ in range(n))
    return rng.randbytes(n)


def test_crc_matches_python_on_many_random_inputs(crosscheck: CrossCheck) -> None:
    rng = random.Random(1)
    for _ in range(400):
        data = _random_bytes(rng, rng.randrange(0, 200))
        assert crosscheck.ask(f"C {hexs(data)}") == [f"C {crc16_ccitt_false(data)}"]


def test_cobs_matches_the_cobs_package_including_254_byte_blocks(crosscheck: CrossCheck) -> None:
    rng = random.Random(2)
    lengths = [0, 1, 253, 254, 255, 507, 508, 509, *(rng.randrange(0, 700) for _ in range(300))]
    for n in lengths:
        data = _random_bytes(rng, n) if rng.random() < 0.7 else bytes([0x11]) * n
        assert crosscheck.ask(f"B {hexs(data)}") == [f"B {hexs(cobs.encode(data))}"], n


# ---- encoding: C and Python write the same bytes --------------------------------------------

i16 = st.integers(-(2**15), 2**15 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)
u16 = st.integers(0, 2**16 - 1)
commands = st.builds(WheelCommand, i16, i16, st.sampled_from([0, 1]))
feedbacks = st.builds(Feedback, i16, i16, i32, i32, st.integers(0, 2**32 - 1), st.integers(0, 255))
hellos = st.builds(
    Hello,
    st.sampled_from([1, 2]),
    st.integers(0, 255),
    u16,
    st.tuples(st.integers(0, 255), st.integers(0, 255), st.integers(0, 255)),
)
messages = st.one_of(commands, feedbacks, hellos)


def c_pack_command(message: Message, seq: int) -> str:
    """The crosscheck command that makes C encode ``message`` with ``seq``."""
    if isinstance(message, Feedback):
        m = message
        fields = (m.right_mm_s, m.left_mm_s, m.right_count, m.left_count, m.mcu_time_ms, m.status)
        return "PF " + " ".join(str(v) for v in (seq, *fields))
    if isinstance(message, WheelCommand):
        return f"PC {seq} {int(message.kind)} {message.right} {message.left}"
    assert isinstance(message, Hello)
    h = message
    return f"PH {seq} {int(h.role)} {int(h.capabilities)} {h.feedback_period_ms} " + " ".join(
        str(v) for v in h.firmware_version
    )


def message_line(message: Message) -> str:
    """How crosscheck prints a decoded message."""
    if isinstance(message, Feedback):
        m = message
        fields = (m.right_mm_s, m.left_mm_s, m.right_count, m.left_count, m.mcu_time_ms, m.status)
        return "M feedback " + " ".join(str(v) for v in fields)
    if isinstance(message, WheelCommand):
        return f"M command {int(message.kind)} {message.right} {message.left}"
    assert isinstance(message, Hello)
    h = message
    return f"M hello {int(h.role)} {int(h.capabilities)} {h.feedback_period_ms} " + " ".join(
        str(v) for v in h.firmware_version
    )


@given(messages, u16)
@settings(max_examples=300)
def test_c_encodes_every_message_exactly_as_python(
    crosscheck: CrossCheck, message: Message, seq: int
) -> None:
    assert wire_of(crosscheck.ask(c_pack_command(message, seq))) == encode_message(message, seq)


@given(st.integers(0, 255), st.integers(0, 255), u16, st.binary(max_size=64))
@settings(max_examples=200)
def test_c_encodes_any_frame_exactly_as_python(
    crosscheck: CrossCheck, version: int, msg_type: int, seq: int, payload: bytes
) -> None:
    wire = wire_of(crosscheck.ask(f"E {version} {msg_type} {seq} {hexs(payload)}"))
    assert wire == encode_frame(msg_type, seq, payload, version=version)


def test_c_refuses_a_payload_longer_than_the_envelope(crosscheck: CrossCheck) -> None:
    assert crosscheck.ask(f"E 1 3 0 {'00' * 65}") == ["W -"]


# ---- decoding: the same frames and statistics from the same stream --------------------------

STATS = [  # the order crosscheck prints them in
    "frames_ok",
    "bytes_skipped",
    "crc_failures",
    "false_frames",
    "oversized_frames",
    "version_mismatches",
    "seq_gaps",
    "frames_lost",
    "seq_resets",
]


@st.composite
def hostile_streams(draw: st.DrawFn) -> bytes:
    """Valid frames, with garbage, cut, corrupted, oversized and foreign frames among them."""
    seq = draw(u16)
    parts: list[bytes] = []
    for _ in range(draw(st.integers(0, 12))):
        message = draw(messages)
        wire = encode_message(message, seq)
        seq = (seq + draw(st.sampled_from([1, 1, 1, 2, 5, 0, 40000]))) & 0xFFFF
        kind = draw(
            st.sampled_from(["ok", "ok", "garbage", "cut", "flip", "crc", "version", "big"])
        )
        if kind == "garbage":
            parts.append(draw(st.binary(max_size=30)))
        elif kind == "cut":
            wire = wire[: draw(st.integers(1, len(wire) - 1))]
        elif kind == "flip":
            k = draw(st.integers(1, len(wire) - 2))
            wire = wire[:k] + bytes([wire[k] ^ draw(st.integers(1, 255))]) + wire[k + 1 :]
        elif kind == "crc":  # intact COBS, wrong CRC
            raw = bytearray(cobs.decode(wire[1:-1]))
            raw[-1] ^= 0x01
            wire = b"\x00" + cobs.encode(bytes(raw)) + b"\x00"
        elif kind == "version":
            msg_type, payload = pack_message(message)
            wire = encode_frame(msg_type, seq, payload, version=draw(st.integers(2, 255)))
        elif kind == "big":
            parts.append(b"\x07" * draw(st.integers(72, 200)))  # longer than any frame
        parts.append(wire)
    return b"".join(parts)


def python_decode(stream: bytes) -> tuple[list[str], list[int]]:
    decoder = RobustDecoder()
    lines = []
    for item in decoder.feed(stream):
        if isinstance(item, Feedback | WheelCommand | Hello):
            msg_type, payload = pack_message(item)
            lines.append((int(msg_type), hexs(payload), message_line(item)))
    stats = [getattr(decoder.stats, name) for name in STATS]
    return [f"{t} {p}|{m}" for t, p, m in lines], stats


def c_decode(crosscheck: CrossCheck, stream: bytes) -> tuple[list[str], list[int]]:
    crosscheck.ask("R")
    answer = crosscheck.ask(f"D {hexs(stream)}") if stream else []
    frames = []
    for f_line, m_line in zip(answer[::2], answer[1::2], strict=True):
        _, version, msg_type, _seq, payload = f_line.split(" ")
        assert version == "1"
        frames.append(f"{msg_type} {payload}|{m_line}")
    (s_line,) = crosscheck.ask("S")
    return frames, [int(v) for v in s_line.split(" ")[1:]]


@given(hostile_streams())
@settings(max_examples=300)
def test_c_decodes_python_streams_exactly_as_python(crosscheck: CrossCheck, stream: bytes) -> None:
    assert c_decode(crosscheck, stream) == python_decode(stream)


def test_c_decodes_random_bytes_exactly_as_python(crosscheck: CrossCheck) -> None:
    rng = random.Random(3)
    for _ in range(100):
        stream = _random_bytes(rng, rng.randrange(0, 3000))
        assert c_decode(crosscheck, stream) == python_decode(stream)


@given(st.lists(messages, max_size=10), u16)
def test_python_decodes_c_encoded_messages(
    crosscheck: CrossCheck, sent: list[Message], start: int
) -> None:
    stream = b"".join(
        wire_of(crosscheck.ask(c_pack_command(m, (start + k) & 0xFFFF))) for k, m in enumerate(sent)
    )
    decoder = RobustDecoder()
    assert decoder.feed(stream) == sent
    assert decoder.stats.frames_lost == 0


# ---- the README's STM32 outline compiles against the codec's API ----------------------------

HAL_STUB = """
#include <stddef.h>
#include <stdint.h>
typedef enum { HAL_OK, HAL_ERROR, HAL_BUSY } HAL_StatusTypeDef;
typedef enum { HAL_UART_STATE_READY = 0x20 } HAL_UART_StateTypeDef;
typedef struct { volatile HAL_UART_StateTypeDef gState; } UART_HandleTypeDef;
typedef struct { int unused; } TIM_HandleTypeDef;
typedef struct { int unused; } IWDG_HandleTypeDef;
extern UART_HandleTypeDef huart2;
extern TIM_HandleTypeDef htim6;
extern IWDG_HandleTypeDef hiwdg;
HAL_StatusTypeDef HAL_UART_Receive_IT(UART_HandleTypeDef *h, uint8_t *p, uint16_t n);
HAL_StatusTypeDef HAL_UART_Transmit_DMA(UART_HandleTypeDef *h, const uint8_t *p, uint16_t n);
HAL_StatusTypeDef HAL_TIM_Base_Start_IT(TIM_HandleTypeDef *h);
HAL_StatusTypeDef HAL_IWDG_Refresh(IWDG_HandleTypeDef *h);
uint32_t HAL_GetTick(void);
int32_t encoder_count_right(void);
int32_t encoder_count_left(void);
void motor_set_duty_centi(int16_t right, int16_t left);
void pid_set_targets_mm_s(int16_t right, int16_t left);
void motor_stop(void);
void update_speeds(void);
void pid_update(void);
void pid_reset(void);
int16_t speed_right_mm_s(void);
int16_t speed_left_mm_s(void);
"""


def _readme_outline() -> str:
    readme = (FIRMWARE / "README.md").read_text()
    blocks = [b.split("```", 1)[0] for b in readme.split("```c\n")[1:]]
    assert len(blocks) >= 3, "the README lost its C snippets"
    return "\n".join(blocks)


def test_readme_stm32_outline_compiles(build_dir: Path) -> None:
    source = build_dir / "readme_outline.c"
    source.write_text(HAL_STUB + _readme_outline())
    cmd = [
        _compiler(),
        *CFLAGS,
        "-I",
        str(FIRMWARE),
        "-c",
        str(source),
        "-o",
        str(build_dir / "o.o"),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr


# A board around the outline: the HAL and the user's motor and PID functions as stubs, a clock
# of 1 ms per pass of the main loop, the 10 ms timer interrupt, and bytes fed to the UART's
# receive interrupt. It prints what the UART sent (hex) and, per scenario, what the motors did.
HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

UART_HandleTypeDef huart2 = {HAL_UART_STATE_READY};
TIM_HandleTypeDef htim6;
IWDG_HandleTypeDef hiwdg;
static uint32_t now_ms;
static int16_t target[2], duty[2];
static int pass, passes, stopped_and_driving, driven;
static uint8_t cmd_wire[PF_MAX_WIRE];
static size_t cmd_len;

HAL_StatusTypeDef HAL_UART_Receive_IT(UART_HandleTypeDef *h, uint8_t *p, uint16_t n)
{ (void)h; (void)p; (void)n; return HAL_OK; }
HAL_StatusTypeDef HAL_UART_Transmit_DMA(UART_HandleTypeDef *h, const uint8_t *p, uint16_t n)
{
    uint16_t i;
    for (i = 0; i < n; ++i) printf("%02x", p[i]);
    h->gState = (HAL_UART_StateTypeDef)0x21; /* busy until the board says the DMA is done */
    return HAL_OK;
}
HAL_StatusTypeDef HAL_TIM_Base_Start_IT(TIM_HandleTypeDef *h) { (void)h; return HAL_OK; }
uint32_t HAL_GetTick(void) { return now_ms; }
int32_t encoder_count_right(void) { return 0; }
int32_t encoder_count_left(void) { return 0; }
void motor_set_duty_centi(int16_t r, int16_t l) { duty[0] = r; duty[1] = l; }
void pid_set_targets_mm_s(int16_t r, int16_t l) { target[0] = r; target[1] = l; }
void motor_stop(void) { duty[0] = duty[1] = 0; }
void update_speeds(void) {}
void pid_update(void) { duty[0] = target[0]; duty[1] = target[1]; } /* drives to the target */
void pid_reset(void) { target[0] = target[1] = 0; }
int16_t speed_right_mm_s(void) { return 0; }
int16_t speed_left_mm_s(void) { return 0; }

static void receive(const uint8_t *bytes, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        rx_byte = bytes[i];
        HAL_UART_RxCpltCallback(&huart2);
    }
}

/* the end of a pass of the main loop: the clock, the DMA, the timer, what the motors do */
HAL_StatusTypeDef HAL_IWDG_Refresh(IWDG_HandleTypeDef *h)
{
    (void)h;
    if ((status_bits & PF_STATUS_WATCHDOG_STOP) && (duty[0] || duty[1])) stopped_and_driving++;
    if (duty[0] || duty[1]) driven++;
    if (++pass == passes) {
        printf("\n%d %d\n", driven, stopped_and_driving);
        exit(0);
    }
    huart2.gState = HAL_UART_STATE_READY;
    now_ms++;
    if (now_ms % 10u == 0u) HAL_TIM_PeriodElapsedCallback(&htim6);
    return HAL_OK;
}

int main(int argc, char **argv)
{
    static uint8_t buf[PF_MAX_WIRE];
    if (strcmp(argv[1], "gap") == 0) { /* the UART still busy at the second of three ticks */
        send_feedback(100, 100);
        send_feedback(110, 110);
        huart2.gState = HAL_UART_STATE_READY;
        send_feedback(120, 120);
        printf("\n");
    } else if (strcmp(argv[1], "hello") == 0) { /* the PC says hello */
        pf_hello pc = {PF_ROLE_PC, 0, 0, 0, 0, 0};
        pf_decoder_init(&dec, dec_buf, sizeof dec_buf);
        receive(buf, pf_encode_hello(&pc, 0, buf, sizeof buf));
        (void)argc;
        passes = 1;
        outline_main();
    } else { /* one speed command, then silence for 300 ms */
        pf_wheel_command cmd = {PF_KIND_SPEED_MM_S, 500, -500};
        cmd_len = pf_encode_wheel_command(&cmd, 0, cmd_wire, sizeof cmd_wire);
        receive(cmd_wire, cmd_len);
        passes = 300;
        outline_main();
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def readme_board(build_dir: Path) -> Path:
    source = build_dir / "readme_board.c"
    source.write_text(
        HAL_STUB + "#define main outline_main\n" + _readme_outline() + "\n#undef main\n" + HARNESS
    )
    exe = build_dir / "readme_board"
    cmd = [_compiler(), "-std=c99", "-O1", "-I", str(FIRMWARE), str(FIRMWARE / "pf_link.c")]
    result = subprocess.run(
        [*cmd, str(source), "-o", str(exe)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    return exe


def _on_board(exe: Path, scenario: str) -> list[str]:
    result = subprocess.run([str(exe), scenario], capture_output=True, text=True, check=True)
    return result.stdout.split("\n")


def test_the_readme_outlines_hello_announces_what_the_emulated_firmware_does(
    readme_board: Path,
) -> None:
    # The PC's --command auto picks speed commands only when the hello announces them: a robot
    # built from the outline must be driven as the emulator's fixed firmware is.
    wire, _ = _on_board(readme_board, "hello")[:2]
    (hello,) = RobustDecoder().feed(bytes.fromhex(wire))
    emulated = EmulatedMCU(firmware="fixed", framing="robust").hello()
    assert hello.capabilities == emulated.capabilities
    assert hello.feedback_period_ms == emulated.feedback_period_ms


def test_the_readme_outline_spends_the_sequence_number_of_a_skipped_feedback(
    readme_board: Path,
) -> None:
    decoder = RobustDecoder()
    sent = decoder.feed(bytes.fromhex(_on_board(readme_board, "gap")[0]))
    assert [m.right_mm_s for m in sent] == [100, 120]
    assert (decoder.stats.seq_gaps, decoder.stats.frames_lost) == (1, 1)


def test_the_readme_outlines_watchdog_keeps_the_pid_from_driving_again(readme_board: Path) -> None:
    wire, counts = _on_board(readme_board, "watchdog")[:2]
    driven, stopped_and_driving = (int(v) for v in counts.split())
    assert 90 <= driven <= 110  # the PID drove the wheels until the 100 ms watchdog stopped them
    assert stopped_and_driving == 0
    statuses = [m.status for m in RobustDecoder().feed(bytes.fromhex(wire))]
    assert (len(statuses), statuses[0]) == (29, 0)
    assert statuses[-1] == Feedback.STATUS_WATCHDOG_STOP
