//! The line-based TCP link every controller and laser driver speaks over: commands ended by the
//! device's terminator (LF, CR or CR LF), replies ended by any of them, a read timeout, and the
//! traffic counted. Owns the socket, the transcript and the byte accounting; the protocols are the
//! drivers'.
//!
//! Every line sent and received is logged at trace level only: a recording's replies are
//! thousands of rows, summarised per recording by the bench ([`Traffic`]); the drivers log the
//! commands that change a device's state at debug level themselves.

use super::HwError;
use std::io::{BufRead, BufReader, ErrorKind, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Every command sent and reply received on a link, for logs and test fixtures: `> command` and
/// `< reply line` entries.
pub type Transcript = Arc<Mutex<Vec<String>>>;

/// What ends a command line the device reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineEnd {
    /// LF (PI GCS 2, SmarAct MCS, Keysight).
    Lf,
    /// A bare CR (Santec TSL over LAN).
    Cr,
    /// CR LF (SmarAct MCS2).
    CrLf,
}

impl LineEnd {
    fn bytes(self) -> &'static [u8] {
        match self {
            LineEnd::Lf => b"\n",
            LineEnd::Cr => b"\r",
            LineEnd::CrLf => b"\r\n",
        }
    }
}

/// The traffic of a link since it was created: what a recording cost on the wire.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Command lines sent.
    pub commands: u64,
    /// Bytes sent (terminators included).
    pub bytes_out: u64,
    /// Bytes received (terminators and binary blocks included).
    pub bytes_in: u64,
    /// Reply lines received.
    pub lines_in: u64,
}

impl Traffic {
    /// The traffic since `earlier`.
    pub fn since(&self, earlier: &Traffic) -> Traffic {
        Traffic {
            commands: self.commands.saturating_sub(earlier.commands),
            bytes_out: self.bytes_out.saturating_sub(earlier.bytes_out),
            bytes_in: self.bytes_in.saturating_sub(earlier.bytes_in),
            lines_in: self.lines_in.saturating_sub(earlier.lines_in),
        }
    }
}

/// A line longer than this is not a reply of these protocols (a `DRR?` data line is < 200 bytes).
const MAX_LINE_BYTES: usize = 1 << 20;

/// A line-oriented TCP link with a read timeout.
pub struct Link {
    pub(crate) controller: String,
    address: String,
    pub(crate) timeout_s: f64,
    send_end: LineEnd,
    pub(crate) reader: Option<BufReader<TcpStream>>,
    transcript: Option<Transcript>,
    traffic: Traffic,
    /// The last reply ended in CR or a binary block: a CR or LF at the start of the next read
    /// belongs to it, not to the next reply.
    skip_leading_terminator: bool,
}

impl Link {
    /// Connect to `address` (host:port); commands end with LF.
    pub fn connect(controller: &str, address: &str, timeout_s: f64) -> Result<Self, HwError> {
        Self::connect_with(controller, address, timeout_s, LineEnd::Lf)
    }

    /// Connect to `address`; commands end with `send_end`. Replies may end with LF, CR or CR LF.
    pub fn connect_with(controller: &str, address: &str, timeout_s: f64, send_end: LineEnd) -> Result<Self, HwError> {
        let mut link = Link {
            controller: controller.to_string(),
            address: address.to_string(),
            timeout_s,
            send_end,
            reader: None,
            transcript: None,
            traffic: Traffic::default(),
            skip_leading_terminator: false,
        };
        link.reconnect()?;
        Ok(link)
    }

    /// Close and open the connection again.
    pub fn reconnect(&mut self) -> Result<(), HwError> {
        self.reader = None;
        self.skip_leading_terminator = false;
        let err = |reason: String| HwError::Connect {
            controller: self.controller.clone(),
            address: self.address.clone(),
            reason,
        };
        let timeout = Duration::from_secs_f64(self.timeout_s.max(1e-3));
        let addr = self
            .address
            .to_socket_addrs()
            .map_err(|e| err(e.to_string()))?
            .next()
            .ok_or_else(|| err("the address resolves to nothing".into()))?;
        let stream = TcpStream::connect_timeout(&addr, timeout).map_err(|e| err(e.to_string()))?;
        tracing::info!(controller = %self.controller, address = %self.address, "connected");
        stream.set_read_timeout(Some(timeout)).map_err(|e| err(e.to_string()))?;
        stream.set_write_timeout(Some(timeout)).map_err(|e| err(e.to_string()))?;
        let _ = stream.set_nodelay(true);
        self.reader = Some(BufReader::with_capacity(64 << 10, stream));
        Ok(())
    }

    /// True while the connection is open.
    pub fn is_open(&self) -> bool {
        self.reader.is_some()
    }

    /// Close the connection.
    pub fn close(&mut self) {
        self.reader = None;
    }

    /// Record every command and reply in `transcript`.
    pub fn set_transcript(&mut self, transcript: Option<Transcript>) {
        self.transcript = transcript;
    }

    /// The read timeout (s).
    pub fn timeout_s(&self) -> f64 {
        self.timeout_s
    }

    /// The traffic since the link was created.
    pub fn traffic(&self) -> Traffic {
        self.traffic
    }

    pub(crate) fn count_in(&mut self, bytes: usize) {
        self.traffic.bytes_in += bytes as u64;
    }

    fn log(&self, entry: String) {
        if let Some(t) = &self.transcript {
            if let Ok(mut t) = t.lock() {
                t.push(entry);
            }
        }
    }

    /// Send one command line (the device's terminator appended).
    pub fn send(&mut self, command: &str) -> Result<(), HwError> {
        let controller = self.controller.clone();
        let reader = self.reader.as_mut().ok_or(HwError::NotConnected { controller: controller.clone() })?;
        let end = self.send_end.bytes();
        let mut line = Vec::with_capacity(command.len() + end.len());
        line.extend_from_slice(command.as_bytes());
        line.extend_from_slice(end);
        if let Err(e) = reader.get_mut().write_all(&line) {
            self.reader = None;
            tracing::warn!(controller = %controller, command, "send failed: {e}");
            return Err(HwError::Disconnected { controller, command: command.into(), reason: e.to_string() });
        }
        self.traffic.commands += 1;
        self.traffic.bytes_out += line.len() as u64;
        tracing::trace!(controller = %self.controller, "> {command}");
        self.log(format!("> {command}"));
        Ok(())
    }

    /// Read one reply line (without its terminator; a trailing space is kept). `command` names
    /// the request in errors.
    pub fn read_line(&mut self, command: &str) -> Result<String, HwError> {
        let reply = self.read_line_inner(command);
        match &reply {
            Ok(line) => {
                self.traffic.lines_in += 1;
                tracing::trace!(controller = %self.controller, "< {line}");
                self.log(format!("< {line}"));
            }
            Err(e) => {
                self.reader = None;
                tracing::warn!(controller = %self.controller, command, "no reply: {e}");
            }
        }
        reply
    }

    fn read_line_inner(&mut self, command: &str) -> Result<String, HwError> {
        let controller = self.controller.clone();
        let timeout_s = self.timeout_s;
        let disconnected = |reason: &str| HwError::Disconnected {
            controller: controller.clone(),
            command: command.into(),
            reason: reason.into(),
        };
        let reader = self.reader.as_mut().ok_or(HwError::NotConnected { controller: controller.clone() })?;
        let mut buf: Vec<u8> = Vec::new();
        let mut counted = 0usize;
        let result = loop {
            let available = match reader.fill_buf() {
                Ok(b) => b,
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    break Err(HwError::Timeout { controller: controller.clone(), command: command.into(), timeout_s });
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => break Err(disconnected(&e.to_string())),
            };
            if available.is_empty() {
                break Err(disconnected(if buf.is_empty() {
                    "closed by the peer"
                } else {
                    "closed by the peer in the middle of a reply"
                }));
            }
            if buf.is_empty() && self.skip_leading_terminator && matches!(available[0], b'\n' | b'\r') {
                reader.consume(1);
                counted += 1;
                continue;
            }
            self.skip_leading_terminator = false;
            match available.iter().position(|&b| b == b'\n' || b == b'\r') {
                Some(i) => {
                    buf.extend_from_slice(&available[..i]);
                    let cr = available[i] == b'\r';
                    reader.consume(i + 1);
                    counted += i + 1;
                    if cr {
                        // CR LF: take the LF when it is already here, else skip it on the next read.
                        if reader.buffer().first() == Some(&b'\n') {
                            reader.consume(1);
                            counted += 1;
                        } else {
                            self.skip_leading_terminator = true;
                        }
                    }
                    break Ok(());
                }
                None => {
                    let n = available.len();
                    buf.extend_from_slice(available);
                    reader.consume(n);
                    counted += n;
                    if buf.len() >= MAX_LINE_BYTES {
                        break Err(HwError::BadReply {
                            controller: controller.clone(),
                            command: command.into(),
                            reply: String::from_utf8_lossy(&buf[..80]).into_owned() + "…",
                            expected: format!("a reply line shorter than {MAX_LINE_BYTES} bytes"),
                        });
                    }
                }
            }
        };
        self.traffic.bytes_in += counted as u64;
        result.map(|()| String::from_utf8_lossy(&buf).into_owned())
    }

    /// After a binary block: a terminator the device sends after it (or not) is skipped by the
    /// next read rather than taken for an empty reply.
    pub(crate) fn after_block(&mut self) {
        self.skip_leading_terminator = true;
    }

    /// A terminator left over from the last reply (CR LF split across reads, or a block's), skipped
    /// before a binary block is read.
    pub(crate) fn skip_pending_terminator(&mut self) -> Result<(), std::io::Error> {
        if !self.skip_leading_terminator {
            return Ok(());
        }
        let Some(reader) = self.reader.as_mut() else { return Ok(()) };
        loop {
            let available = reader.fill_buf()?;
            match available.first() {
                Some(b'\n' | b'\r') => {
                    reader.consume(1);
                    self.traffic.bytes_in += 1;
                }
                _ => break,
            }
        }
        self.skip_leading_terminator = false;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;
    use std::net::TcpListener;

    /// Replies ended by LF, CR or CR LF (split across packets too) read as the same lines; the
    /// traffic is counted.
    #[test]
    fn replies_end_with_lf_cr_or_crlf() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let server = std::thread::spawn(move || {
            let (mut s, _) = listener.accept().unwrap();
            s.set_nodelay(true).unwrap();
            for chunk in [&b"one\r"[..], b"two\r\nthree\n", b"four\r", b"\nfive\r"] {
                s.write_all(chunk).unwrap();
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            let mut buf = [0u8; 16];
            let n = std::io::Read::read(&mut s, &mut buf).unwrap();
            buf[..n].to_vec()
        });
        let mut link = Link::connect_with("dev", &addr, 2.0, LineEnd::CrLf).unwrap();
        let lines: Vec<String> = (0..5).map(|_| link.read_line("q").unwrap()).collect();
        assert_eq!(lines, ["one", "two", "three", "four", "five"]);
        link.send("go").unwrap();
        assert_eq!(server.join().unwrap(), b"go\r\n", "commands end with the device's terminator");
        let t = link.traffic();
        assert_eq!((t.commands, t.bytes_out, t.lines_in, t.bytes_in), (1, 4, 5, 26));
    }
}
