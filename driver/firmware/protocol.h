/*
 * Wire protocol constants: the C mirror of driver/src/protocol.rs (see driver/PROTOCOL.md).
 * A Rust unit test (protocol::tests::c_header_matches) parses this file and checks every
 * value below against the Rust side: keep one "#define NAME VALUE" per line.
 *
 * Frame on the wire: COBS(type u8 | seq u8 | body | crc16 LE) followed by 0x00.
 * CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over type|seq|body. Integers little-endian.
 */
#ifndef PCR_PROTOCOL_H
#define PCR_PROTOCOL_H

#define PROTO_VERSION 1
#define PROTO_MAX_PAYLOAD 48
/* payload + crc + COBS overhead (1 byte for frames < 254 bytes) */
#define PROTO_MAX_ENCODED 51

/* requests (host -> firmware) */
#define MSG_HELLO 0x01
#define MSG_SETPOINT 0x02
#define MSG_ZERO 0x03
#define MSG_ENABLE 0x04
#define MSG_CONFIG 0x05
#define MSG_STATUS 0x06
#define MSG_CLEAR_FAULT 0x07
/* replies (firmware -> host) */
#define MSG_HELLO_REPLY 0x81
#define MSG_STATE 0x82
#define MSG_STATUS_REPLY 0x86
#define MSG_ERROR 0xFF

/* body lengths */
#define LEN_HELLO 1
#define LEN_SETPOINT 13
#define LEN_ZERO 13
#define LEN_ENABLE 1
#define LEN_CONFIG 15
#define LEN_STATUS 0
#define LEN_CLEAR_FAULT 0

/* status flags */
#define FLAG_ENABLED 0x01
#define FLAG_MOVING 0x02
#define FLAG_LIMITED 0x04
#define FLAG_WATCHDOG 0x08
#define FLAG_COILS_ON 0x10
#define FLAG_FAULT 0x20
#define FLAG_WDT_RESET 0x40

/* error codes */
#define ERR_CRC 1
#define ERR_FRAMING 2
#define ERR_UNKNOWN_TYPE 3
#define ERR_BAD_LENGTH 4
#define ERR_SEQUENCE 5
#define ERR_RANGE 6
#define ERR_FAULT 7
#define ERR_BUSY 8
#define ERR_BAD_CONFIG 9
#define ERR_VERSION 10

/* configuration defaults */
#define DEFAULT_MAX_RATE 600
#define DEFAULT_WATCHDOG_MS 200
#define DEFAULT_IDLE_OFF_MS 0
#define DEFAULT_POS_MIN -20480
#define DEFAULT_POS_MAX 20480
#define DEFAULT_CYCLE_MS 20

/* configuration bounds (CONFIG is refused outside them) */
#define CFG_MAX_RATE_MIN 1
#define CFG_MAX_RATE_MAX 1000
#define CFG_CYCLE_MS_MIN 5
#define CFG_CYCLE_MS_MAX 100

#endif
