//! SCPI over a raw TCP socket, as the tunable lasers speak it: terminated commands and replies,
//! `:SYST:ERR?` answers `<code>,"<message>"`, and bulk data as IEEE 488.2 definite-length binary
//! blocks `#<n><len><bytes>`, followed by a terminator or (the Santec, as QMI reads it) by nothing.
//! Owns the parsers of those replies; they take bytes from the network and never panic.

use crate::hardware::{HwError, Link};
use std::io::{ErrorKind, Read};

/// Most bytes a binary block may announce (a lambda log of 1 M points of 8 bytes is 8 MB).
pub const MAX_BLOCK_BYTES: usize = 64 << 20;

/// A `:SYST:ERR?` reply: `+0,"No error"` → `(0, "No error")`. The code may carry a sign; the
/// message may be quoted or not.
pub fn parse_error_reply(reply: &str) -> Result<(i64, String), String> {
    let reply = reply.trim();
    let (code, message) = match reply.split_once(',') {
        Some((c, m)) => (c.trim(), m.trim()),
        None => (reply, ""),
    };
    let code = code
        .strip_prefix('+')
        .unwrap_or(code)
        .parse::<i64>()
        .map_err(|_| format!("`<code>,\"<message>\"` with an integer code, found `{reply}`"))?;
    let message = message.strip_prefix('"').and_then(|m| m.strip_suffix('"')).unwrap_or(message);
    Ok((code, message.to_string()))
}

/// The header of a definite-length block at the start of `bytes`: (header length, data length).
/// `None` while more bytes are needed; an error when it is not a definite-length block header.
pub fn parse_block_header(bytes: &[u8]) -> Result<Option<(usize, usize)>, String> {
    let Some(&first) = bytes.first() else { return Ok(None) };
    if first != b'#' {
        return Err(format!("a binary block starting with `#`, found byte 0x{first:02x}"));
    }
    let Some(&n) = bytes.get(1) else { return Ok(None) };
    let digits = match n {
        b'1'..=b'9' => (n - b'0') as usize,
        b'0' => return Err("a definite-length block (`#<n><len>`), found the indefinite form `#0`".into()),
        _ => return Err(format!("a digit 1-9 after `#`, found byte 0x{n:02x}")),
    };
    let Some(len_text) = bytes.get(2..2 + digits) else { return Ok(None) };
    let len_text = std::str::from_utf8(len_text).map_err(|_| "decimal digits for the block length".to_string())?;
    if !len_text.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!("{digits} decimal digits for the block length, found `{len_text}`"));
    }
    let len: usize = len_text.parse().map_err(|_| format!("a block length, found `{len_text}`"))?;
    if len > MAX_BLOCK_BYTES {
        return Err(format!("a block of at most {MAX_BLOCK_BYTES} bytes, announced {len}"));
    }
    Ok(Some((2 + digits, len)))
}

/// The data of a complete block reply (`#<n><len><bytes>`, an optional trailing newline).
pub fn parse_block(bytes: &[u8]) -> Result<&[u8], String> {
    let (head, len) = parse_block_header(bytes)?.ok_or("a complete block header")?;
    let data = bytes
        .get(head..head + len)
        .ok_or_else(|| format!("{len} bytes of data as announced, found {}", bytes.len().saturating_sub(head)))?;
    match &bytes[head + len..] {
        [] | [b'\n'] | [b'\r', b'\n'] => Ok(data),
        rest => Err(format!("nothing after the block but a newline, found {} more bytes", rest.len())),
    }
}

/// Little-endian f64 values (the Keysight lambda log: metres).
pub fn decode_f64_le(data: &[u8]) -> Result<Vec<f64>, String> {
    if data.len() % 8 != 0 {
        return Err(format!("a multiple of 8 bytes (f64 values), found {}", data.len()));
    }
    Ok(data.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8]))).collect())
}

/// A wavelength log of `points` points (nm) from its block, whichever of the two encodings the
/// byte count says: 8-byte little-endian doubles in metres (Keysight; Santec's SCPI command set) or
/// 4-byte little-endian integers in 0.1 pm (Santec's Legacy set).
pub fn decode_log(data: &[u8], points: usize) -> Result<Vec<f64>, String> {
    if data.len() == 8 * points {
        Ok(decode_f64_le(data)?.into_iter().map(|m| m * 1e9).collect())
    } else if data.len() == 4 * points {
        Ok(decode_u32_le(data)?.into_iter().map(|v| v as f64 * 1e-4).collect())
    } else {
        Err(format!("{points} points of 8 bytes (f64 metres) or 4 bytes (u32 0.1 pm), found {} bytes", data.len()))
    }
}

/// Little-endian u32 values (the Santec wavelength log: units of 0.1 pm).
pub fn decode_u32_le(data: &[u8]) -> Result<Vec<u32>, String> {
    if data.len() % 4 != 0 {
        return Err(format!("a multiple of 4 bytes (u32 values), found {}", data.len()));
    }
    Ok(data.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap_or([0; 4]))).collect())
}

/// A definite-length block, for an emulator or a test: `#<n><len><data>`.
pub fn encode_block(data: &[u8]) -> Vec<u8> {
    let len = data.len().to_string();
    let mut out = format!("#{}{len}", len.len()).into_bytes();
    out.extend_from_slice(data);
    out
}

/// Read one binary block reply from `link`, at most [`MAX_BLOCK_BYTES`]. A terminator after it, if
/// the device sends one, is skipped by the next read. Faults close the link as a line read does.
pub(crate) fn read_block(link: &mut Link, command: &str) -> Result<Vec<u8>, HwError> {
    let controller = link.controller.clone();
    let timeout_s = link.timeout_s;
    if let Err(e) = link.skip_pending_terminator() {
        link.reader = None;
        return Err(io_error(e, &controller, command, timeout_s));
    }
    let reader = link.reader.as_mut().ok_or(HwError::NotConnected { controller: controller.clone() })?;
    let mut buf = Vec::new();
    let bad = |reply: &[u8], expected: String| HwError::BadReply {
        controller: controller.clone(),
        command: command.into(),
        reply: String::from_utf8_lossy(&reply[..reply.len().min(80)]).into_owned(),
        expected,
    };
    let result = (|| -> Result<Vec<u8>, HwError> {
        let mut byte = [0u8; 1];
        let (_head, len) = loop {
            match parse_block_header(&buf) {
                Ok(Some(h)) => break h,
                Ok(None) => {}
                Err(e) => return Err(bad(&buf, e)),
            }
            read_exact(reader, &mut byte, &controller, command, timeout_s)?;
            buf.push(byte[0]);
        };
        let mut data = vec![0u8; len];
        read_exact(reader, &mut data, &controller, command, timeout_s)?;
        Ok(data)
    })();
    match &result {
        Ok(data) => {
            link.count_in(buf.len() + data.len());
            link.after_block();
            tracing::trace!(controller = %controller, "< #{} bytes", data.len());
        }
        Err(_) => link.reader = None,
    }
    result
}

fn io_error(e: std::io::Error, controller: &str, command: &str, timeout_s: f64) -> HwError {
    match e.kind() {
        ErrorKind::WouldBlock | ErrorKind::TimedOut => {
            HwError::Timeout { controller: controller.into(), command: command.into(), timeout_s }
        }
        _ => HwError::Disconnected { controller: controller.into(), command: command.into(), reason: e.to_string() },
    }
}

fn read_exact(
    reader: &mut impl Read,
    buf: &mut [u8],
    controller: &str,
    command: &str,
    timeout_s: f64,
) -> Result<(), HwError> {
    reader.read_exact(buf).map_err(|e| match e.kind() {
        ErrorKind::WouldBlock | ErrorKind::TimedOut => {
            HwError::Timeout { controller: controller.into(), command: command.into(), timeout_s }
        }
        ErrorKind::UnexpectedEof => HwError::Disconnected {
            controller: controller.into(),
            command: command.into(),
            reason: "closed by the peer in the middle of a binary block".into(),
        },
        _ => HwError::Disconnected { controller: controller.into(), command: command.into(), reason: e.to_string() },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn error_replies_and_blocks_parse() {
        assert_eq!(parse_error_reply("+0,\"No error\"").unwrap(), (0, "No error".into()));
        assert_eq!(parse_error_reply("-113,\"Undefined header\"").unwrap(), (-113, "Undefined header".into()));
        assert!(parse_error_reply("No error").is_err());
        let block = encode_block(&1.55e-6f64.to_le_bytes());
        assert_eq!(&block[..3], b"#18");
        assert_eq!(decode_f64_le(parse_block(&block).unwrap()).unwrap(), [1.55e-6]);
        assert!(parse_block(b"#15abc").unwrap_err().contains("5 bytes of data"));
        assert!(parse_block(b"#0abc").unwrap_err().contains("indefinite"));
        assert!(parse_block(b"#2x1").unwrap_err().contains("decimal digits"));
        assert!(parse_block(b"#9999999999").unwrap_err().contains("at most"));
        let metres: Vec<u8> = [1.55e-6f64, 1.551e-6].iter().flat_map(|m| m.to_le_bytes()).collect();
        let nm = decode_log(&metres, 2).unwrap();
        assert!((nm[0] - 1550.0).abs() < 1e-9 && (nm[1] - 1551.0).abs() < 1e-9);
        let tenths: Vec<u8> = [15_500_000u32, 15_510_000].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(decode_log(&tenths, 2).unwrap(), [1550.0, 1551.0]);
        assert!(decode_log(&tenths, 3).unwrap_err().contains("found 8 bytes"));
    }

    proptest! {
        #[test]
        fn the_reply_parsers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
            let _ = parse_block(&bytes);
            let _ = parse_block_header(&bytes);
            let _ = decode_f64_le(&bytes);
            let _ = decode_u32_le(&bytes);
            let _ = decode_log(&bytes, bytes.len() / 4);
            let _ = parse_error_reply(&String::from_utf8_lossy(&bytes));
        }

        #[test]
        fn blocks_round_trip(data in proptest::collection::vec(any::<u8>(), 0..2000)) {
            let mut block = encode_block(&data);
            block.push(b'\n');
            prop_assert_eq!(parse_block(&block).unwrap(), &data[..]);
        }
    }
}
