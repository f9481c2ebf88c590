/*
 * Host unit tests of pf_link (assert-based). Build and run:
 *   cc -std=c99 -Wall -Wextra -Werror -pedantic -I firmware firmware/pf_link.c \
 *      firmware/test/host_test.c -o host_test && ./host_test
 * Prints "OK" when every check passes; an assert failure aborts with its line.
 */
#undef NDEBUG
#include <assert.h>
#include <stdio.h>
#include <string.h>

#include "pf_link.h"

static size_t push_all(pf_decoder *dec, const uint8_t *bytes, size_t n, pf_frame *frames,
                       uint8_t payloads[][PF_MAX_PAYLOAD], size_t max_frames)
{
    size_t count = 0;
    size_t i;
    for (i = 0; i < n; ++i) {
        const pf_frame *f = pf_decoder_push(dec, bytes[i]);
        if (f != 0 && count < max_frames) {
            frames[count] = *f;
            memcpy(payloads[count], f->payload, f->payload_len);
            frames[count].payload = payloads[count];
            ++count;
        }
    }
    return count;
}

static void test_crc(void)
{
    const uint8_t check[] = "123456789";
    const uint8_t empty[1] = {0};
    assert(pf_crc16(check, 9) == 0x29B1u); /* the catalogue check value of CCITT-FALSE */
    assert(pf_crc16(empty, 0) == 0xFFFFu);
    assert(pf_crc16_update(0xFFFFu, 0x31u) == pf_crc16(check, 1));
}

static void test_cobs_vectors(void)
{
    /* Examples from the COBS paper / common test vectors. */
    uint8_t out[600];
    const uint8_t a[] = {0x00};
    const uint8_t a_enc[] = {0x01, 0x01};
    const uint8_t b[] = {0x00, 0x00};
    const uint8_t b_enc[] = {0x01, 0x01, 0x01};
    const uint8_t c[] = {0x11, 0x22, 0x00, 0x33};
    const uint8_t c_enc[] = {0x03, 0x11, 0x22, 0x02, 0x33};
    const uint8_t d[] = {0x11, 0x00, 0x00, 0x00};
    const uint8_t d_enc[] = {0x02, 0x11, 0x01, 0x01, 0x01};
    uint8_t run[254];
    size_t n;

    assert(pf_cobs_encode(a, 0, out, sizeof out) == 1 && out[0] == 0x01);
    assert(pf_cobs_encode(a, 1, out, sizeof out) == 2 && memcmp(out, a_enc, 2) == 0);
    assert(pf_cobs_encode(b, 2, out, sizeof out) == 3 && memcmp(out, b_enc, 3) == 0);
    assert(pf_cobs_encode(c, 4, out, sizeof out) == 5 && memcmp(out, c_enc, 5) == 0);
    assert(pf_cobs_encode(d, 4, out, sizeof out) == 5 && memcmp(out, d_enc, 5) == 0);
    memset(run, 0x01, sizeof run);
    n = pf_cobs_encode(run, 254, out, sizeof out); /* one full block, no last block */
    assert(n == 255 && out[0] == 0xFF && out[254] == 0x01);
    n = pf_cobs_encode(run, 253, out, sizeof out);
    assert(n == 254 && out[0] == 0xFE);
    assert(pf_cobs_encode(c, 4, out, 4) == 0); /* does not fit: refused, not truncated */
}

static void test_round_trip_messages(void)
{
    uint8_t wire[PF_MAX_WIRE * 3];
    uint8_t buf[PF_MAX_FRAME];
    pf_decoder dec;
    pf_frame frames[4];
    uint8_t payloads[4][PF_MAX_PAYLOAD];
    pf_feedback fb = {-1480, 1480, -123456789, 2147483647, 4294967295ul, PF_STATUS_WATCHDOG_STOP};
    pf_wheel_command cmd = {PF_KIND_SPEED_MM_S, -32768, 32767};
    pf_hello hello = {PF_ROLE_MCU, PF_CAP_DUTY_COMMANDS | PF_CAP_WATCHDOG, 10, 1, 2, 3};
    pf_feedback fb2;
    pf_wheel_command cmd2;
    pf_hello hello2;
    size_t n = 0;
    size_t count;

    n += pf_encode_hello(&hello, 0, wire + n, sizeof wire - n);
    n += pf_encode_feedback(&fb, 1, wire + n, sizeof wire - n);
    n += pf_encode_wheel_command(&cmd, 2, wire + n, sizeof wire - n);
    assert(pf_decoder_init(&dec, buf, sizeof buf) == 0);
    count = push_all(&dec, wire, n, frames, payloads, 4);
    assert(count == 3);
    assert(pf_unpack_hello(&frames[0], &hello2) == 0);
    assert(hello2.role == PF_ROLE_MCU && hello2.feedback_period_ms == 10 && hello2.fw_patch == 3);
    assert(pf_unpack_feedback(&frames[1], &fb2) == 0);
    assert(fb2.right_mm_s == -1480 && fb2.left_mm_s == 1480);
    assert(fb2.right_count == -123456789 && fb2.left_count == 2147483647);
    assert(fb2.mcu_time_ms == 4294967295ul && fb2.status == PF_STATUS_WATCHDOG_STOP);
    assert(pf_unpack_wheel_command(&frames[2], &cmd2) == 0);
    assert(cmd2.kind == PF_KIND_SPEED_MM_S && cmd2.right == -32768 && cmd2.left == 32767);
    assert(pf_unpack_feedback(&frames[2], &fb2) == -1); /* not a feedback */
    assert(dec.stats.frames_ok == 3 && dec.stats.bytes_skipped == 0);
    assert(dec.stats.seq_gaps == 0 && dec.stats.frames_lost == 0);
}

static void test_corruption_is_counted_and_dropped(void)
{
    uint8_t wire[PF_MAX_WIRE];
    uint8_t buf[PF_MAX_FRAME];
    pf_decoder dec;
    pf_frame frames[2];
    uint8_t payloads[2][PF_MAX_PAYLOAD];
    /* No zero byte anywhere in this frame, so COBS makes it one block: every byte after the
     * code byte is data, and flipping one leaves the COBS structure intact. */
    pf_feedback fb = {0x0101, 0x0202, 0x01010101, 0x02020202, 0x03030303ul, 0x01};
    size_t n = pf_encode_feedback(&fb, 0x0101, wire, sizeof wire);

    assert(wire[1] == n - 2u); /* a single COBS block */
    wire[8] ^= 0x40u;          /* a data byte: the CRC must catch it */
    assert(pf_decoder_init(&dec, buf, sizeof buf) == 0);
    assert(push_all(&dec, wire, n, frames, payloads, 2) == 0);
    assert(dec.stats.crc_failures == 1 && dec.last_status == PF_ERR_CRC);
    assert(dec.stats.bytes_skipped == n - 1u); /* the run and its delimiter, not the lead 0 */
}

static void test_version_mismatch_is_refused(void)
{
    uint8_t wire[PF_MAX_WIRE];
    uint8_t buf[PF_MAX_FRAME];
    uint8_t payload[PF_FEEDBACK_LEN] = {0};
    pf_decoder dec;
    pf_frame frames[2];
    uint8_t payloads[2][PF_MAX_PAYLOAD];
    size_t n = pf_encode_frame(2, PF_MSG_FEEDBACK, 0, payload, sizeof payload, wire, sizeof wire);

    assert(pf_decoder_init(&dec, buf, sizeof buf) == 0);
    assert(push_all(&dec, wire, n, frames, payloads, 2) == 0);
    assert(dec.stats.version_mismatches == 1 && dec.last_status == PF_ERR_VERSION);
}

static void test_sequence_gaps_wrap_around(void)
{
    static const uint16_t seqs[] = {65533, 65534, 0, 3, 4, 4, 10};
    uint8_t wire[PF_MAX_WIRE * 8];
    uint8_t buf[PF_MAX_FRAME];
    pf_decoder dec;
    pf_frame frames[8];
    uint8_t payloads[8][PF_MAX_PAYLOAD];
    pf_feedback fb = {0, 0, 0, 0, 0, 0};
    size_t n = 0;
    size_t i;

    for (i = 0; i < sizeof seqs / sizeof seqs[0]; ++i) {
        n += pf_encode_feedback(&fb, seqs[i], wire + n, sizeof wire - n);
    }
    assert(pf_decoder_init(&dec, buf, sizeof buf) == 0);
    assert(push_all(&dec, wire, n, frames, payloads, 8) == 7);
    /* 65534 -> 0 skips 65535 (1 lost), 0 -> 3 (2 lost), 4 -> 10 (5 lost); 4 -> 4 repeats. */
    assert(dec.stats.seq_gaps == 3 && dec.stats.frames_lost == 8);
    assert(dec.stats.seq_resets == 1);
}

static void test_garbage_between_frames(void)
{
    uint8_t wire[4 * PF_MAX_WIRE + 200];
    uint8_t buf[PF_MAX_FRAME];
    pf_decoder dec;
    pf_frame frames[4];
    uint8_t payloads[4][PF_MAX_PAYLOAD];
    pf_feedback fb = {1, 2, 3, 4, 5, 0};
    pf_feedback out;
    size_t n = 0;
    size_t i;

    for (i = 0; i < 100u; ++i) { /* an oversized run: 100 bytes, no delimiter */
        wire[n++] = (uint8_t)(0x80u + i);
    }
    n += pf_encode_feedback(&fb, 0, wire + n, sizeof wire - n);
    wire[n++] = 0x05; /* a cut frame: COBS code promising more bytes than come */
    wire[n++] = 0x11;
    n += pf_encode_feedback(&fb, 1, wire + n, sizeof wire - n);
    wire[n++] = 0x02; /* too short for the envelope */
    wire[n++] = 0x01;
    n += pf_encode_feedback(&fb, 2, wire + n, sizeof wire - n);

    assert(pf_decoder_init(&dec, buf, sizeof buf) == 0);
    assert(push_all(&dec, wire, n, frames, payloads, 4) == 3);
    for (i = 0; i < 3u; ++i) {
        assert(pf_unpack_feedback(&frames[i], &out) == 0 && out.mcu_time_ms == 5u);
        assert(frames[i].seq == i);
    }
    assert(dec.stats.oversized_frames == 1 && dec.stats.false_frames == 2);
    assert(dec.stats.bytes_skipped == 101u + 3u + 3u);
}

static void test_init_refuses_small_buffer(void)
{
    uint8_t buf[PF_MAX_FRAME - 1];
    pf_decoder dec;
    assert(pf_decoder_init(&dec, buf, sizeof buf) == -1);
}

int main(void)
{
    test_crc();
    test_cobs_vectors();
    test_round_trip_messages();
    test_corruption_is_counted_and_dropped();
    test_version_mismatch_is_refused();
    test_sequence_gaps_wrap_around();
    test_garbage_between_frames();
    test_init_refuses_small_buffer();
    printf("OK\n");
    return 0;
}
