//! The target's side of the link, independent of transport and of the navigator: packet
//! reassembly, sequence numbers, acknowledgements, frame assembly with end-to-end CRC, and
//! counters. The firmware drives it over any `embedded_io` reader and writer; the host tests
//! drive it over byte slices.
//!
//! Guarantees: a frame is handed to the navigator only when every chunk arrived in order under a
//! good packet CRC and the reassembled payload matches the header's CRC; any other frame is
//! abandoned and counted, so a fix can never come from stale or corrupted data.

use crate::PROTOCOL_VERSION;
use crate::msg::{
    Ack, ErrorCode, ErrorReport, FrameHeader, Hello, HelloAck, LinkError, Message, Nack,
    NackReason, SampleFormat, Status,
};
use crate::packet::{CRC32, MAX_CHUNK_BYTES, PacketError, Received, Receiver, encode_wire};
use core::fmt;

/// Largest message the target sends, bytes before COBS (a [`crate::msg::FrameResult`] with an
/// odometry fix, its offset and a hazard map is the largest; `tests/protocol.rs` checks it fits).
pub const TX_PACKET_BYTES: usize = 448;
/// Receive block size: bytes asked of the reader per call.
pub const RX_BLOCK_BYTES: usize = 512;

/// What the target tells the host about itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TargetInfo {
    /// CRC-32 of the linked reference tile.
    pub tile_crc: u32,
    /// Features in the tile.
    pub tile_features: u32,
    /// Widest frame accepted, pixels.
    pub max_frame_width: u16,
    /// CRC-32 at the end of the linked atlas's index (0: no atlas).
    pub atlas_crc: u32,
    /// Tiles in the linked atlas.
    pub atlas_tiles: u16,
}

/// A complete, verified frame ready for the navigator.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadyFrame {
    /// The frame's header.
    pub header: FrameHeader,
}

/// What [`TargetLink::poll`] returns.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// A frame is in [`TargetLink::heights_m`]; answer it with [`TargetLink::send`].
    Frame(ReadyFrame),
    /// The host ended the session (the final [`Status`] has been sent).
    Shutdown,
    /// The reader reported end of stream.
    EndOfStream,
}

/// Transport failures (the link itself is gone, not merely noisy).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IoFailure {
    /// The reader failed.
    Read,
    /// The writer failed.
    Write,
    /// A message did not fit the transmit buffer (a bug, not a link condition).
    Encode,
}

impl fmt::Display for IoFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Read => "link read failed",
            Self::Write => "link write failed",
            Self::Encode => "message too large for the transmit buffer",
        })
    }
}

impl core::error::Error for IoFailure {}

struct Assembly {
    header: FrameHeader,
    received: u32,
    digest: crc::Digest<'static, u32>,
}

/// The target's link state over a caller-owned frame buffer of `f32` heights.
pub struct TargetLink<'b> {
    info: TargetInfo,
    rx: Receiver,
    rbuf: [u8; RX_BLOCK_BYTES],
    rpos: usize,
    rlen: usize,
    scratch: [u8; TX_PACKET_BYTES],
    wire: [u8; crate::cobs::max_encoded_len(TX_PACKET_BYTES) + 2],
    expect_seq: u16,
    last_seq: Option<u16>,
    tx_seq: u16,
    session: bool,
    status: Status,
    frame: Option<Assembly>,
    heights: &'b mut [f32],
    ready_px: usize,
}

/// The CRC algorithm as a `static`, so running digests can borrow it for `'static`.
static PAYLOAD_CRC: crc::Crc<u32> = CRC32;

impl<'b> TargetLink<'b> {
    /// A link over `heights` (the frame buffer: its length is the largest frame in pixels).
    pub fn new(info: TargetInfo, heights: &'b mut [f32]) -> Self {
        Self {
            info,
            rx: Receiver::new(),
            rbuf: [0; RX_BLOCK_BYTES],
            rpos: 0,
            rlen: 0,
            scratch: [0; TX_PACKET_BYTES],
            wire: [0; crate::cobs::max_encoded_len(TX_PACKET_BYTES) + 2],
            expect_seq: 0,
            last_seq: None,
            tx_seq: 0,
            session: false,
            status: Status::default(),
            frame: None,
            heights,
            ready_px: 0,
        }
    }

    /// Counters so far.
    pub fn status(&self) -> Status {
        self.status
    }

    /// The heights of the last [`Event::Frame`], metres, row-major.
    pub fn heights_m(&self) -> &[f32] {
        self.heights.get(..self.ready_px).unwrap_or(&[])
    }

    /// Send one message.
    pub fn send<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        msg: &Message<'_>,
    ) -> Result<(), IoFailure> {
        let n = encode_wire(self.tx_seq, msg, &mut self.scratch, &mut self.wire)
            .map_err(|_| IoFailure::Encode)?;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let bytes = self.wire.get(..n).ok_or(IoFailure::Encode)?;
        w.write_all(bytes).map_err(|_| IoFailure::Write)?;
        w.flush().map_err(|_| IoFailure::Write)
    }

    /// Read and handle bytes until a frame is ready, the session ends or the stream ends.
    pub fn poll<R: embedded_io::Read, W: embedded_io::Write>(
        &mut self,
        r: &mut R,
        w: &mut W,
    ) -> Result<Event, IoFailure> {
        loop {
            if self.rpos >= self.rlen {
                let n = r.read(&mut self.rbuf).map_err(|_| IoFailure::Read)?;
                if n == 0 {
                    return Ok(Event::EndOfStream);
                }
                self.rpos = 0;
                self.rlen = n;
            }
            while self.rpos < self.rlen {
                let byte = self.rbuf.get(self.rpos).copied().unwrap_or(0);
                self.rpos += 1;
                if let Some(ev) = self.feed(byte, w)? {
                    return Ok(ev);
                }
            }
        }
    }

    fn feed<W: embedded_io::Write>(
        &mut self,
        byte: u8,
        w: &mut W,
    ) -> Result<Option<Event>, IoFailure> {
        // Copy out what the packet says so the receiver's buffer is free again before sending.
        let action = match self.rx.push(byte) {
            Received::Pending => return Ok(None),
            Received::Error(e) => Err(e),
            Received::Packet(seq, msg) => Ok((seq, Self::classify(seq, &msg))),
        };
        match action {
            Err(e) => {
                self.count_link_error(&e);
                let nack = Nack {
                    expect_seq: self.expect_seq,
                    reason: NackReason::Link(e.link_error()),
                };
                self.send(w, &Message::Nack(nack))?;
                Ok(None)
            }
            Ok((seq, kind)) if self.last_seq == Some(seq) && !matches!(kind, Kind::Hello(_)) => {
                self.status.duplicates = self.status.duplicates.saturating_add(1);
                self.send(w, &Message::Ack(Ack { seq }))?;
                Ok(None)
            }
            Ok((seq, kind)) => self.accept(seq, kind, w),
        }
    }

    /// Decide what to do with a good packet while its bytes are still borrowed: chunk data is
    /// copied into the frame buffer only after the sequence check, so keep it by value here.
    fn classify(_seq: u16, msg: &Message<'_>) -> Kind {
        match *msg {
            Message::Hello(h) => Kind::Hello(h),
            Message::FrameHeader(h) => Kind::Header(h),
            Message::FrameChunk(c) => {
                let mut data = ChunkCopy {
                    frame_id: c.frame_id,
                    offset: c.offset,
                    len: c.data.len(),
                    bytes: [0; MAX_CHUNK_BYTES],
                };
                match data.bytes.get_mut(..c.data.len()) {
                    Some(dst) => {
                        dst.copy_from_slice(c.data);
                        Kind::Chunk(data)
                    }
                    None => Kind::OversizeChunk(c.frame_id),
                }
            }
            Message::StatusRequest => Kind::StatusRequest,
            Message::Shutdown => Kind::Shutdown,
            _ => Kind::WrongDirection,
        }
    }

    fn count_link_error(&mut self, e: &PacketError) {
        let s = &mut self.status;
        let c = match e.link_error() {
            LinkError::Cobs => &mut s.cobs_errors,
            LinkError::Overrun => &mut s.overruns,
            LinkError::Short => &mut s.short_packets,
            LinkError::Crc => &mut s.crc_errors,
            LinkError::Decode => &mut s.decode_errors,
            LinkError::SeqGap => &mut s.seq_gaps,
        };
        *c = c.saturating_add(1);
    }

    fn error<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
        code: ErrorCode,
        frame_id: u32,
    ) -> Result<(), IoFailure> {
        self.send(w, &Message::Error(ErrorReport { code, frame_id }))
    }

    fn abort_frame(&mut self) {
        if self.frame.take().is_some() {
            self.status.frames_aborted = self.status.frames_aborted.saturating_add(1);
        }
    }

    fn accept<W: embedded_io::Write>(
        &mut self,
        seq: u16,
        kind: Kind,
        w: &mut W,
    ) -> Result<Option<Event>, IoFailure> {
        let is_hello = matches!(kind, Kind::Hello(_));
        if !is_hello && seq != self.expect_seq {
            self.status.seq_gaps = self.status.seq_gaps.saturating_add(1);
            let nack = Nack {
                expect_seq: self.expect_seq,
                reason: NackReason::Link(LinkError::SeqGap),
            };
            self.send(w, &Message::Nack(nack))?;
            return Ok(None);
        }
        self.expect_seq = seq.wrapping_add(1);
        self.last_seq = Some(seq);
        self.status.packets_ok = self.status.packets_ok.saturating_add(1);
        self.send(w, &Message::Ack(Ack { seq }))?;
        match kind {
            Kind::Hello(h) => self.on_hello(h, w).map(|()| None),
            Kind::Header(h) => self.on_header(h, w).map(|()| None),
            Kind::Chunk(c) => self.on_chunk(&c, w),
            Kind::OversizeChunk(id) => {
                self.abort_frame();
                self.error(w, ErrorCode::UnexpectedChunk, id).map(|()| None)
            }
            Kind::StatusRequest => {
                let s = self.status;
                self.send(w, &Message::Status(s)).map(|()| None)
            }
            Kind::Shutdown => {
                self.abort_frame();
                let s = self.status;
                self.send(w, &Message::Status(s))?;
                Ok(Some(Event::Shutdown))
            }
            Kind::WrongDirection => self.error(w, ErrorCode::WrongDirection, 0).map(|()| None),
        }
    }

    fn on_hello<W: embedded_io::Write>(&mut self, h: Hello, w: &mut W) -> Result<(), IoFailure> {
        self.abort_frame();
        self.session = h.version == PROTOCOL_VERSION;
        let ack = HelloAck {
            version: PROTOCOL_VERSION,
            accepted: self.session,
            session: h.session,
            tile_crc: self.info.tile_crc,
            tile_features: self.info.tile_features,
            max_frame_px: self.heights.len().min(u32::MAX as usize) as u32,
            max_frame_width: self.info.max_frame_width,
            max_chunk_bytes: MAX_CHUNK_BYTES as u16,
            atlas_crc: self.info.atlas_crc,
            atlas_tiles: self.info.atlas_tiles,
        };
        self.send(w, &Message::HelloAck(ack))?;
        if !self.session {
            self.error(w, ErrorCode::VersionMismatch, 0)?;
        }
        Ok(())
    }

    fn on_header<W: embedded_io::Write>(
        &mut self,
        h: FrameHeader,
        w: &mut W,
    ) -> Result<(), IoFailure> {
        self.abort_frame();
        if !self.session {
            return self.error(w, ErrorCode::NoSession, h.frame_id);
        }
        let px = h.width as usize * h.height as usize;
        if px > self.heights.len() || h.width > self.info.max_frame_width {
            self.status.frames_aborted = self.status.frames_aborted.saturating_add(1);
            return self.error(w, ErrorCode::FrameTooLarge, h.frame_id);
        }
        let SampleFormat::HeightF32Le = h.format;
        if h.payload_bytes as usize != px * 4 {
            self.status.frames_aborted = self.status.frames_aborted.saturating_add(1);
            return self.error(w, ErrorCode::BadFrameHeader, h.frame_id);
        }
        self.frame = Some(Assembly {
            header: h,
            received: 0,
            digest: PAYLOAD_CRC.digest(),
        });
        Ok(())
    }

    fn on_chunk<W: embedded_io::Write>(
        &mut self,
        c: &ChunkCopy,
        w: &mut W,
    ) -> Result<Option<Event>, IoFailure> {
        let data = c.bytes.get(..c.len).unwrap_or(&[]);
        let ok = match &self.frame {
            Some(a) => {
                a.header.frame_id == c.frame_id
                    && c.offset == a.received
                    && c.len.is_multiple_of(4)
                    && (c.offset as usize).saturating_add(c.len) <= a.header.payload_bytes as usize
            }
            None => false,
        };
        if !ok {
            self.abort_frame();
            self.error(w, ErrorCode::UnexpectedChunk, c.frame_id)?;
            return Ok(None);
        }
        let Some(a) = self.frame.as_mut() else {
            return Ok(None);
        };
        let first = c.offset as usize / 4;
        for (k, word) in data.chunks_exact(4).enumerate() {
            if let (Some(slot), Ok(b)) = (self.heights.get_mut(first + k), word.try_into()) {
                *slot = f32::from_le_bytes(b);
            }
        }
        a.digest.update(data);
        a.received += c.len as u32;
        if a.received < a.header.payload_bytes {
            return Ok(None);
        }
        let header = a.header;
        let Some(done) = self.frame.take() else {
            return Ok(None);
        };
        let crc = done.digest.finalize();
        if crc != header.payload_crc {
            self.status.frames_aborted = self.status.frames_aborted.saturating_add(1);
            self.error(w, ErrorCode::PayloadCrc, header.frame_id)?;
            return Ok(None);
        }
        self.status.frames_done = self.status.frames_done.saturating_add(1);
        self.ready_px = header.width as usize * header.height as usize;
        Ok(Some(Event::Frame(ReadyFrame { header })))
    }
}

struct ChunkCopy {
    frame_id: u32,
    offset: u32,
    len: usize,
    bytes: [u8; MAX_CHUNK_BYTES],
}

// A chunk is copied out of the receive buffer (2 KiB) before the sequence check; no heap to box it.
#[allow(clippy::large_enum_variant)]
enum Kind {
    Hello(Hello),
    Header(FrameHeader),
    Chunk(ChunkCopy),
    OversizeChunk(u32),
    StatusRequest,
    Shutdown,
    WrongDirection,
}

/// CRC-32 of a payload as [`FrameHeader::payload_crc`] expects (same as [`CRC32`]).
pub fn payload_crc(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}
