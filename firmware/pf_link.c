/*
 * pf_link: the robust framing's codec, MCU side (see pf_link.h for the layout).
 * Every check and counter here mirrors bridge/protocol/robust.py exactly: the cross-test in
 * tests/firmware/test_c_codec.py compares decoded frames and statistics byte for byte.
 */
#include "pf_link.h"

/* ---- CRC-16/CCITT-FALSE, bitwise: 16 shifts per byte, no 512-byte table in flash ------ */

uint16_t pf_crc16_update(uint16_t crc, uint8_t byte)
{
    unsigned bit;
    crc = (uint16_t)(crc ^ ((uint16_t)byte << 8));
    for (bit = 0; bit < 8u; ++bit) {
        if (crc & 0x8000u) {
            crc = (uint16_t)((crc << 1) ^ 0x1021u);
        } else {
            crc = (uint16_t)(crc << 1);
        }
    }
    return crc;
}

uint16_t pf_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    size_t i;
    for (i = 0; i < len; ++i) {
        crc = pf_crc16_update(crc, data[i]);
    }
    return crc;
}

/* ---- COBS -------------------------------------------------------------------------------- */

/* Same output as the Python `cobs` package: a block ends at a zero (code = length + 1) or
 * after 254 non-zero bytes (code 0xFF, no zero); a last block is written unless the input
 * ended exactly after a 0xFF block. */
size_t pf_cobs_encode(const uint8_t *src, size_t len, uint8_t *dst, size_t cap)
{
    size_t out = 1;      /* dst[0] is reserved for the first code byte */
    size_t code_at = 0;  /* where the current block's code byte goes */
    uint8_t code = 1;    /* current block length + 1 */
    size_t i;

    if (cap < 1u) {
        return 0;
    }
    for (i = 0; i < len; ++i) {
        if (src[i] == 0u) {
            dst[code_at] = code;
            code_at = out++;
            if (code_at >= cap) {
                return 0;
            }
            code = 1;
        } else {
            if (out >= cap) {
                return 0;
            }
            dst[out++] = src[i];
            ++code;
            if (code == 0xFFu) {
                dst[code_at] = code;
                code = 1;
                if (i + 1u < len) {
                    code_at = out++;
                    if (code_at >= cap) {
                        return 0;
                    }
                } else {
                    return out; /* ended exactly after a 0xFF block: no last block */
                }
            }
        }
    }
    dst[code_at] = code;
    return out;
}

/* ---- Frames ------------------------------------------------------------------------------ */

size_t pf_encode_frame(uint8_t version, uint8_t type, uint16_t seq, const uint8_t *payload,
                       size_t payload_len, uint8_t *out, size_t cap)
{
    uint8_t raw[PF_MAX_FRAME];
    size_t n = 0;
    size_t i;
    size_t encoded;
    uint16_t crc;

    if (payload_len > PF_MAX_PAYLOAD || cap < 2u) {
        return 0;
    }
    raw[n++] = version;
    raw[n++] = type;
    raw[n++] = (uint8_t)(seq >> 8);
    raw[n++] = (uint8_t)(seq & 0xFFu);
    for (i = 0; i < payload_len; ++i) {
        raw[n++] = payload[i];
    }
    crc = pf_crc16(raw, n);
    raw[n++] = (uint8_t)(crc >> 8);
    raw[n++] = (uint8_t)(crc & 0xFFu);

    out[0] = 0x00u; /* leading delimiter: ends whatever garbage came before */
    encoded = pf_cobs_encode(raw, n, out + 1, cap - 2u);
    if (encoded == 0u) {
        return 0;
    }
    out[1u + encoded] = 0x00u;
    return encoded + 2u;
}

int pf_decoder_init(pf_decoder *dec, uint8_t *buf, size_t cap)
{
    pf_stats zero_stats = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    if (cap < PF_MAX_FRAME) {
        return -1;
    }
    dec->buf = buf;
    dec->cap = cap;
    dec->len = 0;
    dec->run = 0;
    dec->remaining = 0;
    dec->zero_next = 0;
    dec->started = 0;
    dec->have_seq = 0;
    dec->last_seq = 0;
    dec->last_status = PF_OK;
    dec->frame.version = 0;
    dec->frame.type = 0;
    dec->frame.seq = 0;
    dec->frame.payload = buf;
    dec->frame.payload_len = 0;
    dec->stats = zero_stats;
    return 0;
}

static uint16_t get_u16(const uint8_t *p)
{
    return (uint16_t)(((uint16_t)p[0] << 8) | p[1]);
}

static uint32_t get_u32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3];
}

/* Two's complement from unsigned without implementation-defined conversions. */
static int16_t to_i16(uint16_t u)
{
    return (u <= 0x7FFFu) ? (int16_t)u : (int16_t)(-(int16_t)(uint16_t)~u - 1);
}

static int32_t to_i32(uint32_t u)
{
    return (u <= 0x7FFFFFFFul) ? (int32_t)u : (int32_t)(-(int32_t)(~u) - 1);
}

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)(v & 0xFFu);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)((v >> 16) & 0xFFu);
    p[2] = (uint8_t)((v >> 8) & 0xFFu);
    p[3] = (uint8_t)(v & 0xFFu);
}

/* A frame of our version is a message only with the type's exact length and sane fields. */
static int message_ok(uint8_t type, const uint8_t *payload, size_t len)
{
    switch (type) {
    case PF_MSG_HELLO:
        return len == PF_HELLO_LEN && (payload[0] == PF_ROLE_PC || payload[0] == PF_ROLE_MCU);
    case PF_MSG_WHEEL_COMMAND:
        return len == PF_WHEEL_COMMAND_LEN &&
               (payload[0] == PF_KIND_DUTY_CENTI_PERCENT || payload[0] == PF_KIND_SPEED_MM_S);
    case PF_MSG_FEEDBACK:
        return len == PF_FEEDBACK_LEN;
    default:
        return 0;
    }
}

/* Lost frames from the sequence numbers, modulo 2^16; a hello starts a new sequence. */
static void track_seq(pf_decoder *dec, uint8_t type, uint16_t seq)
{
    if (type == PF_MSG_HELLO) {
        dec->have_seq = 0;
    }
    if (dec->have_seq) {
        uint16_t delta = (uint16_t)(seq - dec->last_seq);
        if (delta >= 2u && delta <= 0x8000u) {
            dec->stats.seq_gaps++;
            dec->stats.frames_lost += (uint32_t)(delta - 1u);
        } else if (delta != 1u) {
            dec->stats.seq_resets++;
        }
    }
    dec->last_seq = seq;
    dec->have_seq = 1;
}

static const pf_frame *reject(pf_decoder *dec, pf_status why, size_t run)
{
    dec->last_status = why;
    dec->stats.bytes_skipped += (uint32_t)(run + 1u);
    return 0;
}

static const pf_frame *end_run(pf_decoder *dec)
{
    size_t run = dec->run;
    size_t len = dec->len;
    int cobs_ok = (dec->remaining == 0u);
    const uint8_t *b = dec->buf;

    dec->run = 0;
    dec->len = 0;
    dec->remaining = 0;
    dec->zero_next = 0;
    dec->started = 0;

    if (run == 0u) {
        return 0; /* empty frame: two delimiters in a row */
    }
    if (run > PF_MAX_ENCODED) {
        dec->stats.oversized_frames++;
        return reject(dec, PF_ERR_OVERSIZED, run);
    }
    if (!cobs_ok) {
        dec->stats.false_frames++;
        return reject(dec, PF_ERR_COBS, run);
    }
    if (len < PF_HEADER_LEN + PF_CRC_LEN) {
        dec->stats.false_frames++;
        return reject(dec, PF_ERR_SHORT, run);
    }
    if (pf_crc16(b, len - PF_CRC_LEN) != get_u16(b + len - PF_CRC_LEN)) {
        dec->stats.crc_failures++;
        return reject(dec, PF_ERR_CRC, run);
    }
    if (b[0] != PF_PROTOCOL_VERSION) {
        dec->stats.version_mismatches++;
        return reject(dec, PF_ERR_VERSION, run);
    }
    track_seq(dec, b[1], get_u16(b + 2));
    if (!message_ok(b[1], b + PF_HEADER_LEN, len - PF_HEADER_LEN - PF_CRC_LEN)) {
        dec->stats.false_frames++;
        return reject(dec, PF_ERR_MESSAGE, run);
    }
    dec->stats.frames_ok++;
    dec->last_status = PF_OK;
    dec->frame.version = b[0];
    dec->frame.type = b[1];
    dec->frame.seq = get_u16(b + 2);
    dec->frame.payload = b + PF_HEADER_LEN;
    dec->frame.payload_len = len - PF_HEADER_LEN - PF_CRC_LEN;
    return &dec->frame;
}

static void append(pf_decoder *dec, uint8_t byte)
{
    if (dec->len < dec->cap) { /* always true while run <= PF_MAX_ENCODED */
        dec->buf[dec->len++] = byte;
    }
}

const pf_frame *pf_decoder_push(pf_decoder *dec, uint8_t byte)
{
    if (byte == 0x00u) {
        return end_run(dec);
    }
    dec->run++;
    if (dec->run > PF_MAX_ENCODED) {
        return 0; /* oversized: drop bytes until the next delimiter */
    }
    if (dec->remaining == 0u) { /* a COBS code byte */
        if (dec->started && dec->zero_next) {
            append(dec, 0x00u);
        }
        dec->started = 1;
        dec->remaining = (uint8_t)(byte - 1u);
        dec->zero_next = (uint8_t)(byte != 0xFFu);
    } else {
        append(dec, byte);
        dec->remaining--;
    }
    return 0;
}

/* ---- Messages ---------------------------------------------------------------------------- */

size_t pf_pack_hello(const pf_hello *msg, uint8_t *out, size_t cap)
{
    if (cap < PF_HELLO_LEN) {
        return 0;
    }
    out[0] = msg->role;
    out[1] = msg->capabilities;
    put_u16(out + 2, msg->feedback_period_ms);
    out[4] = msg->fw_major;
    out[5] = msg->fw_minor;
    out[6] = msg->fw_patch;
    return PF_HELLO_LEN;
}

size_t pf_pack_wheel_command(const pf_wheel_command *msg, uint8_t *out, size_t cap)
{
    if (cap < PF_WHEEL_COMMAND_LEN) {
        return 0;
    }
    out[0] = msg->kind;
    put_u16(out + 1, (uint16_t)msg->right); /* signed -> unsigned is defined: modulo 2^16 */
    put_u16(out + 3, (uint16_t)msg->left);
    return PF_WHEEL_COMMAND_LEN;
}

size_t pf_pack_feedback(const pf_feedback *msg, uint8_t *out, size_t cap)
{
    if (cap < PF_FEEDBACK_LEN) {
        return 0;
    }
    put_u16(out, (uint16_t)msg->right_mm_s);
    put_u16(out + 2, (uint16_t)msg->left_mm_s);
    put_u32(out + 4, (uint32_t)msg->right_count);
    put_u32(out + 8, (uint32_t)msg->left_count);
    put_u32(out + 12, msg->mcu_time_ms);
    out[16] = msg->status;
    return PF_FEEDBACK_LEN;
}

int pf_unpack_hello(const pf_frame *frame, pf_hello *msg)
{
    const uint8_t *p = frame->payload;
    if (frame->type != PF_MSG_HELLO || !message_ok(frame->type, p, frame->payload_len)) {
        return -1;
    }
    msg->role = p[0];
    msg->capabilities = p[1];
    msg->feedback_period_ms = get_u16(p + 2);
    msg->fw_major = p[4];
    msg->fw_minor = p[5];
    msg->fw_patch = p[6];
    return 0;
}

int pf_unpack_wheel_command(const pf_frame *frame, pf_wheel_command *msg)
{
    const uint8_t *p = frame->payload;
    if (frame->type != PF_MSG_WHEEL_COMMAND || !message_ok(frame->type, p, frame->payload_len)) {
        return -1;
    }
    msg->kind = p[0];
    msg->right = to_i16(get_u16(p + 1));
    msg->left = to_i16(get_u16(p + 3));
    return 0;
}

int pf_unpack_feedback(const pf_frame *frame, pf_feedback *msg)
{
    const uint8_t *p = frame->payload;
    if (frame->type != PF_MSG_FEEDBACK || !message_ok(frame->type, p, frame->payload_len)) {
        return -1;
    }
    msg->right_mm_s = to_i16(get_u16(p));
    msg->left_mm_s = to_i16(get_u16(p + 2));
    msg->right_count = to_i32(get_u32(p + 4));
    msg->left_count = to_i32(get_u32(p + 8));
    msg->mcu_time_ms = get_u32(p + 12);
    msg->status = p[16];
    return 0;
}

size_t pf_encode_feedback(const pf_feedback *msg, uint16_t seq, uint8_t *out, size_t cap)
{
    uint8_t payload[PF_FEEDBACK_LEN];
    size_t n = pf_pack_feedback(msg, payload, sizeof payload);
    return pf_encode_frame(PF_PROTOCOL_VERSION, PF_MSG_FEEDBACK, seq, payload, n, out, cap);
}

size_t pf_encode_hello(const pf_hello *msg, uint16_t seq, uint8_t *out, size_t cap)
{
    uint8_t payload[PF_HELLO_LEN];
    size_t n = pf_pack_hello(msg, payload, sizeof payload);
    return pf_encode_frame(PF_PROTOCOL_VERSION, PF_MSG_HELLO, seq, payload, n, out, cap);
}

size_t pf_encode_wheel_command(const pf_wheel_command *msg, uint16_t seq, uint8_t *out,
                               size_t cap)
{
    uint8_t payload[PF_WHEEL_COMMAND_LEN];
    size_t n = pf_pack_wheel_command(msg, payload, sizeof payload);
    return pf_encode_frame(PF_PROTOCOL_VERSION, PF_MSG_WHEEL_COMMAND, seq, payload, n, out,
                           cap);
}
