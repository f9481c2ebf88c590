/*
 * Cross-check driver: lets tests/firmware/test_c_codec.py compare this C codec with the
 * Python one byte for byte. Reads commands from stdin, one per line, writes answers:
 *
 *   D <hex>            push bytes into the decoder; prints, per completed frame,
 *                      "F <version> <type> <seq> <payload hex or ->" and then the message:
 *                      "M hello <role> <caps> <period_ms> <major> <minor> <patch>",
 *                      "M command <kind> <right> <left>" or
 *                      "M feedback <right> <left> <rcount> <lcount> <time_ms> <status>"
 *   S                  prints the statistics: "S frames_ok bytes_skipped crc_failures
 *                      false_frames oversized_frames version_mismatches seq_gaps frames_lost
 *                      seq_resets"
 *   R                  starts a new decoder
 *   E <ver> <type> <seq> <payload hex or ->   prints "W <wire hex>" (pf_encode_frame)
 *   PH <seq> <role> <caps> <period> <major> <minor> <patch>    prints "W <wire hex>"
 *   PC <seq> <kind> <right> <left>                             prints "W <wire hex>"
 *   PF <seq> <right> <left> <rcount> <lcount> <time_ms> <status> prints "W <wire hex>"
 *   C <hex>            prints "C <crc16 decimal>"
 *   B <hex>            prints "B <COBS hex>"
 * Numbers are decimal. Every command's answer ends with a line "." (so the reader can sync).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pf_link.h"

#define MAX_BYTES 65536

static char line[2 * MAX_BYTES + 64];
static uint8_t bytes[MAX_BYTES];
static uint8_t out[2 * MAX_BYTES];

static size_t parse_hex(const char *s, uint8_t *dst, size_t cap)
{
    size_t n = 0;
    while (*s == ' ') {
        ++s;
    }
    if (*s == '-') {
        return 0;
    }
    while (s[0] && s[1] && n < cap) {
        unsigned v;
        if (sscanf(s, "%2x", &v) != 1) {
            break;
        }
        dst[n++] = (uint8_t)v;
        s += 2;
    }
    return n;
}

static void print_hex(const char *tag, const uint8_t *p, size_t n)
{
    size_t i;
    printf("%s ", tag);
    if (n == 0u) {
        printf("-");
    }
    for (i = 0; i < n; ++i) {
        printf("%02x", p[i]);
    }
    printf("\n");
}

static void print_frame(const pf_frame *f)
{
    pf_hello h;
    pf_wheel_command c;
    pf_feedback fb;
    char tag[32];
    sprintf(tag, "F %u %u %u", f->version, f->type, f->seq);
    print_hex(tag, f->payload, f->payload_len);
    if (pf_unpack_hello(f, &h) == 0) {
        printf("M hello %u %u %u %u %u %u\n", h.role, h.capabilities, h.feedback_period_ms,
               h.fw_major, h.fw_minor, h.fw_patch);
    } else if (pf_unpack_wheel_command(f, &c) == 0) {
        printf("M command %u %d %d\n", c.kind, c.right, c.left);
    } else if (pf_unpack_feedback(f, &fb) == 0) {
        printf("M feedback %d %d %ld %ld %lu %u\n", fb.right_mm_s, fb.left_mm_s,
               (long)fb.right_count, (long)fb.left_count, (unsigned long)fb.mcu_time_ms,
               fb.status);
    }
}

int main(void)
{
    static uint8_t dec_buf[PF_MAX_FRAME];
    pf_decoder dec;
    pf_decoder_init(&dec, dec_buf, sizeof dec_buf);

    while (fgets(line, sizeof line, stdin)) {
        char *nl = strchr(line, '\n');
        if (nl) {
            *nl = '\0';
        }
        if (line[0] == 'D') {
            size_t n = parse_hex(line + 1, bytes, sizeof bytes);
            size_t i;
            for (i = 0; i < n; ++i) {
                const pf_frame *f = pf_decoder_push(&dec, bytes[i]);
                if (f) {
                    print_frame(f);
                }
            }
        } else if (line[0] == 'S') {
            const pf_stats *s = &dec.stats;
            printf("S %lu %lu %lu %lu %lu %lu %lu %lu %lu\n", (unsigned long)s->frames_ok,
                   (unsigned long)s->bytes_skipped, (unsigned long)s->crc_failures,
                   (unsigned long)s->false_frames, (unsigned long)s->oversized_frames,
                   (unsigned long)s->version_mismatches, (unsigned long)s->seq_gaps,
                   (unsigned long)s->frames_lost, (unsigned long)s->seq_resets);
        } else if (line[0] == 'R') {
            pf_decoder_init(&dec, dec_buf, sizeof dec_buf);
        } else if (line[0] == 'E') {
            unsigned ver, type, seq;
            int used = 0;
            if (sscanf(line + 1, "%u %u %u%n", &ver, &type, &seq, &used) == 3) {
                size_t n = parse_hex(line + 1 + used, bytes, sizeof bytes);
                size_t w = pf_encode_frame((uint8_t)ver, (uint8_t)type, (uint16_t)seq, bytes, n,
                                           out, sizeof out);
                print_hex("W", out, w);
            }
        } else if (line[0] == 'P' && line[1] == 'H') {
            unsigned seq, role, caps, period, ma, mi, pa;
            if (sscanf(line + 2, "%u %u %u %u %u %u %u", &seq, &role, &caps, &period, &ma, &mi,
                       &pa) == 7) {
                pf_hello h;
                h.role = (uint8_t)role;
                h.capabilities = (uint8_t)caps;
                h.feedback_period_ms = (uint16_t)period;
                h.fw_major = (uint8_t)ma;
                h.fw_minor = (uint8_t)mi;
                h.fw_patch = (uint8_t)pa;
                print_hex("W", out, pf_encode_hello(&h, (uint16_t)seq, out, sizeof out));
            }
        } else if (line[0] == 'P' && line[1] == 'C') {
            unsigned seq, kind;
            int right, left;
            if (sscanf(line + 2, "%u %u %d %d", &seq, &kind, &right, &left) == 4) {
                pf_wheel_command c;
                c.kind = (uint8_t)kind;
                c.right = (int16_t)right;
                c.left = (int16_t)left;
                print_hex("W", out, pf_encode_wheel_command(&c, (uint16_t)seq, out, sizeof out));
            }
        } else if (line[0] == 'P' && line[1] == 'F') {
            unsigned seq, status;
            int right, left;
            long rc, lc;
            unsigned long t;
            if (sscanf(line + 2, "%u %d %d %ld %ld %lu %u", &seq, &right, &left, &rc, &lc, &t,
                       &status) == 7) {
                pf_feedback fb;
                fb.right_mm_s = (int16_t)right;
                fb.left_mm_s = (int16_t)left;
                fb.right_count = (int32_t)rc;
                fb.left_count = (int32_t)lc;
                fb.mcu_time_ms = (uint32_t)t;
                fb.status = (uint8_t)status;
                print_hex("W", out, pf_encode_feedback(&fb, (uint16_t)seq, out, sizeof out));
            }
        } else if (line[0] == 'C') {
            size_t n = parse_hex(line + 1, bytes, sizeof bytes);
            printf("C %u\n", pf_crc16(bytes, n));
        } else if (line[0] == 'B') {
            size_t n = parse_hex(line + 1, bytes, sizeof bytes);
            print_hex("B", out, pf_cobs_encode(bytes, n, out, sizeof out));
        }
        printf(".\n");
        fflush(stdout);
    }
    return 0;
}
