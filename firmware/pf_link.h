/*
 * pf_link: the robust framing of the PersonFollow serial link, MCU side.
 *
 * Portable C99: no malloc, no HAL calls, no global state; every function works on what the
 * caller passes. The byte layout is the one of bridge/protocol/robust.py (the Python side),
 * and tests/firmware/test_c_codec.py checks the two byte for byte.
 *
 * On the wire every frame is  00 | COBS(frame) | 00 , and a frame (before COBS) is
 *
 *     version u8 | type u8 | seq u16 | payload (0..64 bytes) | CRC-16 u16
 *
 * multi-byte fields big-endian (as the reference protocol, reference §1). The CRC is
 * CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0; check value 0x29B1
 * for "123456789") over every byte before it.
 */
#ifndef PF_LINK_H
#define PF_LINK_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define PF_PROTOCOL_VERSION 1u
#define PF_HEADER_LEN 4u
#define PF_CRC_LEN 2u
#define PF_MAX_PAYLOAD 64u
/* Largest frame before COBS (bytes); a decoder buffer must hold this many. */
#define PF_MAX_FRAME (PF_HEADER_LEN + PF_MAX_PAYLOAD + PF_CRC_LEN)
/* Largest frame after COBS, delimiters excluded: COBS adds 1 byte per 254 (frames < 254). */
#define PF_MAX_ENCODED (PF_MAX_FRAME + 1u)
/* Largest frame on the wire, both delimiters included: size transmit buffers with this. */
#define PF_MAX_WIRE (PF_MAX_ENCODED + 2u)

/* Message types and payload lengths (bytes) of protocol version 1. */
enum pf_msg_type {
    PF_MSG_HELLO = 0x01,
    PF_MSG_WHEEL_COMMAND = 0x02,
    PF_MSG_FEEDBACK = 0x03
};
#define PF_HELLO_LEN 7u
#define PF_WHEEL_COMMAND_LEN 5u
#define PF_FEEDBACK_LEN 17u

/* WheelCommand kinds: what the two values mean. */
enum pf_command_kind {
    PF_KIND_DUTY_CENTI_PERCENT = 0, /* duty in 0.01 %: the PID runs on the PC */
    PF_KIND_SPEED_MM_S = 1          /* wheel speed target in mm/s: the PID runs here */
};

/* Hello roles and capability bits. */
enum pf_role { PF_ROLE_PC = 1, PF_ROLE_MCU = 2 };
#define PF_CAP_DUTY_COMMANDS 0x01u
#define PF_CAP_SPEED_COMMANDS 0x02u
#define PF_CAP_ENCODER_COUNTS 0x04u
#define PF_CAP_WATCHDOG 0x08u

/* Feedback status bits. */
#define PF_STATUS_WATCHDOG_STOP 0x01u

typedef struct {
    uint8_t kind; /* enum pf_command_kind */
    int16_t right;
    int16_t left;
} pf_wheel_command;

typedef struct {
    int16_t right_mm_s;  /* right wheel speed from its encoder, mm/s */
    int16_t left_mm_s;   /* left wheel speed, mm/s */
    int32_t right_count; /* right encoder count since start, counts (4x), wrapping */
    int32_t left_count;  /* left encoder count, counts */
    uint32_t mcu_time_ms; /* when the speeds were measured, ms since start */
    uint8_t status;      /* PF_STATUS_* bits */
} pf_feedback;

typedef struct {
    uint8_t role;                /* enum pf_role */
    uint8_t capabilities;        /* PF_CAP_* bits */
    uint16_t feedback_period_ms; /* ms; 10 on the reference robot */
    uint8_t fw_major, fw_minor, fw_patch;
} pf_hello;

/* What a decoder has seen. Same names and meaning as bridge.protocol.LinkStats. */
typedef struct {
    uint32_t frames_ok;          /* frames handed to the caller */
    uint32_t bytes_skipped;      /* bytes of rejected frames and their delimiter */
    uint32_t crc_failures;       /* CRC mismatch */
    uint32_t false_frames;       /* bad COBS, too short, unknown type, wrong length/field */
    uint32_t oversized_frames;   /* more than PF_MAX_ENCODED bytes between delimiters */
    uint32_t version_mismatches; /* intact frame of another protocol version: refused */
    uint32_t seq_gaps;           /* forward jumps of the sequence number by more than 1 */
    uint32_t frames_lost;        /* sum of (jump - 1), modulo 2^16 */
    uint32_t seq_resets;         /* sequence repeated or went back (restart without hello) */
} pf_stats;

/* Why the last completed run of bytes gave no frame (or PF_OK if it did). */
typedef enum {
    PF_OK = 0,
    PF_ERR_OVERSIZED,
    PF_ERR_COBS,
    PF_ERR_SHORT,
    PF_ERR_CRC,
    PF_ERR_VERSION,
    PF_ERR_MESSAGE /* unknown type, wrong payload length, or a field value no sender sends */
} pf_status;

/* A decoded frame; payload points into the decoder's buffer (valid until the next push). */
typedef struct {
    uint8_t version;
    uint8_t type;
    uint16_t seq;
    const uint8_t *payload;
    size_t payload_len;
} pf_frame;

/* Receive state machine. Initialise with pf_decoder_init; do not touch the fields. */
typedef struct {
    uint8_t *buf;      /* caller's buffer for the frame being decoded */
    size_t cap;        /* its size, >= PF_MAX_FRAME */
    size_t len;        /* decoded bytes so far */
    size_t run;        /* encoded bytes since the last delimiter */
    uint8_t remaining; /* data bytes left in the current COBS block */
    uint8_t zero_next; /* the current block ends with an implied zero */
    uint8_t started;   /* a COBS block has begun in this run */
    uint8_t have_seq;  /* last_seq is valid */
    uint16_t last_seq;
    pf_status last_status;
    pf_frame frame;
    pf_stats stats;
} pf_decoder;

/* CRC-16/CCITT-FALSE. pf_crc16_update continues a CRC by one byte (start from 0xFFFF). */
uint16_t pf_crc16_update(uint16_t crc, uint8_t byte);
uint16_t pf_crc16(const uint8_t *data, size_t len);

/* COBS-encode len bytes into dst (no delimiter). Returns the encoded length, or 0 if it does
 * not fit in cap bytes. Needs at most len + len / 254 + 1 bytes. */
size_t pf_cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap);

/* Encode a whole frame, 00 | COBS | 00, into out. Returns the bytes written, or 0 if the
 * payload is longer than PF_MAX_PAYLOAD or out is shorter than needed (PF_MAX_WIRE always
 * suffices). version is PF_PROTOCOL_VERSION except to emulate other firmware in tests. */
size_t pf_encode_frame(uint8_t version, uint8_t type, uint16_t seq, const uint8_t *payload,
                       size_t payload_len, uint8_t *out, size_t cap);

/* Start a decoder on the caller's buffer. Returns 0, or -1 if cap < PF_MAX_FRAME. */
int pf_decoder_init(pf_decoder *dec, uint8_t *buf, size_t cap);

/* Push one received byte. Returns the frame it completed (valid until the next call), or
 * NULL. Safe to call from a main loop fed by an interrupt's ring buffer; not reentrant. */
const pf_frame *pf_decoder_push(pf_decoder *dec, uint8_t byte);

/* Message payloads: pack into out (returns the payload length, 0 if cap is too small) and
 * unpack from a decoded frame (returns 0, or -1 if the frame is not that message). */
size_t pf_pack_hello(const pf_hello *msg, uint8_t *out, size_t cap);
size_t pf_pack_wheel_command(const pf_wheel_command *msg, uint8_t *out, size_t cap);
size_t pf_pack_feedback(const pf_feedback *msg, uint8_t *out, size_t cap);
int pf_unpack_hello(const pf_frame *frame, pf_hello *msg);
int pf_unpack_wheel_command(const pf_frame *frame, pf_wheel_command *msg);
int pf_unpack_feedback(const pf_frame *frame, pf_feedback *msg);

/* Pack a message and encode its frame in one go (returns bytes written, 0 on error). */
size_t pf_encode_feedback(const pf_feedback *msg, uint16_t seq, uint8_t *out, size_t cap);
size_t pf_encode_hello(const pf_hello *msg, uint16_t seq, uint8_t *out, size_t cap);
size_t pf_encode_wheel_command(const pf_wheel_command *msg, uint16_t seq, uint8_t *out,
                               size_t cap);

#ifdef __cplusplus
}
#endif

#endif /* PF_LINK_H */
