//! The host side of the box's USB protocol (`dynocomp_core::protocol`):
//! open a serial port (the box's CDC port, or the virtual box's
//! pseudo-terminal), send requests, wait for their replies, collect stream
//! frames.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use dynocomp_core::protocol::{
    decode_message, encode_frame, status_protocol_version, BoxMessage, FrameDecoder, LinkError, Reply, Request,
    RequestFrame, Status, StreamFrame, MAX_FRAME, PROTOCOL_VERSION,
};

/// How long the host waits for a reply by default. An upload commit reads
/// back and verifies the image (a few ms on the box); erasing a slot takes
/// up to ~100 ms.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(3);

/// Byte transport: a serial port, or anything that reads and writes.
pub trait Transport: Read + Write + Send {}
impl<T: Read + Write + Send> Transport for T {}

/// A connection to a box.
pub struct Link {
    port: Box<dyn Transport>,
    name: String,
    decoder: FrameDecoder,
    next_id: u16,
    /// Stream frames received while waiting for replies.
    pub stream: VecDeque<StreamFrame>,
    /// Replies with id 0 (frames the box could not read) seen so far.
    pub unreadable_replies: Vec<LinkError>,
    /// Reply timeout.
    pub timeout: Duration,
    /// Protocol version of a status reply that did not decode (a box with
    /// other firmware), until a request reports it.
    foreign_protocol: Option<u16>,
}

/// Open a serial port in raw mode (8N1, no flow control; the baud rate is
/// irrelevant for USB CDC and pseudo-terminals).
///
/// The port is opened exclusively (flock). A port held by another program
/// for a moment (ModemManager probes a new USB CDC device for a few
/// seconds; a previous `dynocomp` still closing) is retried for up to
/// [`PORT_BUSY_WAIT`] before the error says so.
pub fn open_port(path: &str) -> Result<Box<dyn Transport>> {
    let start = std::time::Instant::now();
    loop {
        match serialport::new(path, 115_200).timeout(Duration::from_millis(20)).open() {
            Ok(port) => return Ok(Box::new(port)),
            Err(e) if e.description.contains("lock") && start.elapsed() < PORT_BUSY_WAIT => {
                std::thread::sleep(Duration::from_millis(50))
            }
            Err(e) if e.description.contains("lock") => {
                return Err(anyhow::anyhow!(
                "{path}: cannot open serial port: {e} (busy for {} s: another program holds it; close it and retry)",
                PORT_BUSY_WAIT.as_secs()
            ))
            }
            Err(e) => return Err(anyhow::Error::new(e).context(format!("{path}: cannot open serial port"))),
        }
    }
}

/// How long [`open_port`] waits for a port another program holds.
pub const PORT_BUSY_WAIT: Duration = Duration::from_secs(3);

impl Link {
    /// Connect through a serial port path.
    pub fn open(path: &str) -> Result<Link> {
        Ok(Link::new(open_port(path)?, path))
    }

    /// Wrap a transport (`name` appears in error messages).
    pub fn new(port: Box<dyn Transport>, name: &str) -> Link {
        Link {
            port,
            name: name.to_string(),
            decoder: FrameDecoder::new(),
            next_id: 1,
            stream: VecDeque::new(),
            unreadable_replies: Vec::new(),
            timeout: REPLY_TIMEOUT,
            foreign_protocol: None,
        }
    }

    /// Send raw bytes (tests: malformed frames).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<()> {
        let gone = || format!("{}: write failed (box unplugged or stopped?)", self.name);
        self.port.write_all(bytes).with_context(gone)?;
        self.port.flush().with_context(gone)
    }

    /// Send a request without waiting; returns its id.
    pub fn send(&mut self, request: Request<'_>) -> Result<u16> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_frame(&RequestFrame { id, request }, &mut buf)
            .map_err(|e| anyhow!("{}: request does not fit a frame: {e}", self.name))?;
        self.send_raw(&buf[..n])?;
        Ok(id)
    }

    /// Read what is available (up to `wait`) and return the decoded box
    /// messages; undecodable frames are skipped and counted as garbage.
    pub fn poll(&mut self, wait: Duration) -> Result<Vec<BoxMessage>> {
        let mut buf = [0u8; 4096];
        let n = match self.port.read(&mut buf) {
            Ok(0) => {
                std::thread::sleep(wait.min(Duration::from_millis(5)));
                0
            }
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut || e.kind() == std::io::ErrorKind::WouldBlock => 0,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => 0,
            Err(e) => return Err(anyhow!("{}: read failed: {e} (box unplugged or stopped?)", self.name)),
        };
        let mut out = Vec::new();
        let mut foreign = None;
        self.decoder.push(&buf[..n], |r| {
            let Ok(bytes) = r else { return };
            match decode_message::<BoxMessage>(bytes) {
                Some(m) => out.push(m),
                // A status reply of another protocol version does not
                // decode; its version number still can.
                None => foreign = status_protocol_version(bytes).filter(|&v| v != PROTOCOL_VERSION).or(foreign),
            }
        });
        if foreign.is_some() {
            self.foreign_protocol = foreign;
        }
        Ok(out)
    }

    /// Send `request` and wait for its reply; stream frames that arrive
    /// meanwhile are queued in [`stream`](Self::stream).
    pub fn request(&mut self, request: Request<'_>) -> Result<Reply> {
        let id = self.send(request)?;
        let deadline = Instant::now() + self.timeout;
        let mut answer = None;
        loop {
            // Keep every message of the batch (stream frames may follow the
            // reply in the same read).
            for m in self.poll(Duration::from_millis(5))? {
                match m {
                    BoxMessage::Reply { id: rid, reply } if rid == id && answer.is_none() => answer = Some(reply),
                    BoxMessage::Reply { id: 0, reply: Reply::Error(e) } => {
                        self.unreadable_replies.push(e);
                    }
                    BoxMessage::Reply { .. } => {}
                    BoxMessage::Stream(f) => self.stream.push_back(f),
                }
            }
            if let Some(reply) = answer {
                return Ok(reply);
            }
            if let Some(v) = self.foreign_protocol.take() {
                bail!("{}: {}", self.name, version_mismatch(v));
            }
            if Instant::now() > deadline {
                bail!(
                    "{}: no reply from the box within {:.1} s (is it running this firmware?)",
                    self.name,
                    self.timeout.as_secs_f64()
                );
            }
        }
    }

    /// Send `request` and require an `Ack`.
    pub fn command(&mut self, request: Request<'_>) -> Result<()> {
        match self.request(request)? {
            Reply::Ack => Ok(()),
            Reply::Error(e) => bail!("{}: box refused {}: {}", self.name, request_name(&request), describe_error(&e)),
            other => bail!("{}: unexpected reply to {}: {}", self.name, request_name(&request), reply_name(&other)),
        }
    }

    /// The box's status.
    pub fn status(&mut self) -> Result<Status> {
        match self.request(Request::GetStatus)? {
            Reply::Status(s) if s.protocol != PROTOCOL_VERSION => {
                bail!("{}: {}", self.name, version_mismatch(s.protocol))
            }
            Reply::Status(s) => Ok(s),
            Reply::Error(e) => bail!("{}: status request refused: {}", self.name, describe_error(&e)),
            other => bail!("{}: unexpected reply to GetStatus: {}", self.name, reply_name(&other)),
        }
    }
}

/// The error for a box that speaks protocol version `box_version`.
fn version_mismatch(box_version: u16) -> String {
    format!(
        "the box speaks protocol version {box_version}, this dynocomp speaks version {PROTOCOL_VERSION}: \
         flash the firmware built with this dynocomp (`cargo firmware-run`), or use the dynocomp that matches the box"
    )
}

/// Name of a request for messages.
pub fn request_name(r: &Request<'_>) -> &'static str {
    match r {
        Request::GetStatus => "GetStatus",
        Request::SetBypass(_) => "SetBypass",
        Request::StartStream { .. } => "StartStream",
        Request::StopStream => "StopStream",
        Request::UploadBegin { .. } => "UploadBegin",
        Request::UploadChunk { .. } => "UploadChunk",
        Request::UploadCommit => "UploadCommit",
        Request::AutoZero => "AutoZero",
    }
}

/// Name of a reply for messages.
fn reply_name(r: &Reply) -> &'static str {
    match r {
        Reply::Ack => "an acknowledgement",
        Reply::Status(_) => "a status",
        Reply::Error(_) => "an error",
    }
}

/// One-line explanation of a box error.
pub fn describe_error(e: &LinkError) -> String {
    match e {
        LinkError::Frame(f) => format!("the box could not read our frame ({f})"),
        LinkError::Malformed => "the box could not decode our message (protocol version mismatch?)".into(),
        LinkError::NoUpload => "no upload in progress".into(),
        LinkError::BadDecimation => "decimation must be at least 1".into(),
        LinkError::UploadTooLarge { len, max } => format!("image of {len} bytes does not fit a slot (max {max})"),
        LinkError::OutOfOrder { expected, got } => format!("chunk at offset {got}, box expected {expected}"),
        LinkError::ChunkTooLong { len } => format!("chunk beyond the declared length {len}"),
        LinkError::Incomplete { received, len } => format!("commit after {received} of {len} bytes"),
        LinkError::CrcMismatch { declared, computed } => {
            format!("image corrupted in transfer: CRC {computed:#010x} read back, {declared:#010x} declared")
        }
        LinkError::Image(i) => format!("invalid image: {i}"),
        LinkError::NotRunnable(r) => format!("the box cannot run this image: {r}"),
        LinkError::Flash(f) => format!("flash write failed: {f}"),
        LinkError::UploadAborted => "the upload was aborted; start again".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every box error reads as words, not as Rust's debug form of the
    /// error value (`Image(BadCrc { stored: … })`, `NotAligned`).
    #[test]
    fn box_errors_read_as_words() {
        use dynocomp_core::image::ImageError;
        use dynocomp_core::protocol::{FlashFault, FrameError};
        use dynocomp_core::sample::BypassReason;
        let errors = [
            LinkError::Frame(FrameError::Cobs),
            LinkError::Image(ImageError::BadCrc { stored: 1, computed: 2 }),
            LinkError::NotRunnable(BypassReason::InvalidImage(ImageError::BadCrc { stored: 1, computed: 2 })),
            LinkError::NotRunnable(BypassReason::OfflineOnly),
            LinkError::Flash(FlashFault::NotAligned),
        ];
        for e in &errors {
            let text = describe_error(e);
            let debug = format!("{e:?}");
            let leaf = debug.rsplit('(').next().unwrap().trim_end_matches(')').to_string();
            assert!(!text.contains('{') && !text.contains(&leaf), "{e:?}: {text}");
        }
    }

    /// A transport that answers every read with canned bytes once.
    struct Canned(std::io::Cursor<Vec<u8>>);
    impl Read for Canned {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            self.0.read(buf)
        }
    }
    impl Write for Canned {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn frame<T: serde::Serialize>(msg: &T) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_frame(msg, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn a_box_with_another_protocol_version_is_named_not_timed_out() {
        // The start of a version-1 status reply to request id 1 (Reply,
        // id, Status, protocol 1, firmware, fs): not this version's message.
        let old = frame(&(0u32, 1u16, 1u32, 1u16, [0u8, 1, 0], 51_200u32));
        let mut link = Link::new(Box::new(Canned(std::io::Cursor::new(old))), "box");
        link.timeout = Duration::from_millis(500);
        let err = link.status().unwrap_err().to_string();
        assert!(err.contains("the box speaks protocol version 1, this dynocomp speaks version 2"), "{err}");
    }

    #[test]
    fn a_decodable_status_of_another_version_is_refused() {
        let status = Status {
            protocol: PROTOCOL_VERSION + 1,
            firmware: [9, 9, 9],
            fs_hz: 51_200,
            core_clock_hz: 170_000_000,
            bypass: None,
            active: None,
            image: None,
            counters: Default::default(),
            stream_decimation: None,
            stream_next_seq: 0,
        };
        let reply = frame(&BoxMessage::Reply { id: 1, reply: Reply::Status(status) });
        let mut link = Link::new(Box::new(Canned(std::io::Cursor::new(reply))), "box");
        let err = link.status().unwrap_err().to_string();
        assert!(err.contains("protocol version 3"), "{err}");
    }
}
