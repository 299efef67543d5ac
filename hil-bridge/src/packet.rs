//! Packets: `seq` (u16 LE) · postcard [`Message`] · CRC-32 (u32 LE), COBS-encoded and
//! delimited by `0x00` on the wire.
//!
//! ```text
//! wire:   00 | COBS( seq_lo seq_hi | message … | crc0 crc1 crc2 crc3 ) | 00
//! ```
//!
//! The CRC is CRC-32/ISO-HDLC (zlib's `crc32`) over the sequence number and the message bytes.
//! The leading `0x00` flushes whatever partial packet a receiver holds after line noise, so a
//! packet can never be glued to garbage in front of it.

use crate::cobs::{self, CobsError};
use crate::msg::{LinkError, Message};
use core::fmt;

/// Bytes of the sequence number at the start of a packet.
pub const SEQ_LEN: usize = 2;
/// Bytes of the CRC at the end of a packet.
pub const CRC_LEN: usize = 4;
/// Largest [`crate::msg::FrameChunk::data`], bytes.
pub const MAX_CHUNK_BYTES: usize = 2048;
/// Largest encoded message, bytes: a chunk's data plus its header fields with margin (the
/// largest fixed message, [`crate::msg::FrameResult`] with a fix, fits 320 bytes, see `tests/protocol.rs`).
pub const MAX_MESSAGE_BYTES: usize = MAX_CHUNK_BYTES + 32;
/// Largest packet before COBS, bytes.
pub const MAX_PACKET_BYTES: usize = SEQ_LEN + MAX_MESSAGE_BYTES + CRC_LEN;
/// Largest packet on the wire, bytes: COBS overhead and both delimiters.
pub const MAX_WIRE_BYTES: usize = cobs::max_encoded_len(MAX_PACKET_BYTES) + 2;

/// CRC-32/ISO-HDLC, as zlib's `crc32` and the tile format.
pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Why a packet could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message does not fit [`MAX_MESSAGE_BYTES`] or the output buffer.
    TooLarge,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("message too large for the packet buffer")
    }
}

impl core::error::Error for EncodeError {}

/// Why received bytes are not a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PacketError {
    /// COBS decoding failed.
    Cobs(CobsError),
    /// Longer than the receive buffer.
    Overrun,
    /// Shorter than [`SEQ_LEN`] + [`CRC_LEN`] + 1.
    Short,
    /// CRC mismatch.
    Crc {
        /// CRC carried by the packet.
        stored: u32,
        /// CRC of the bytes received.
        computed: u32,
    },
    /// The CRC matched but the message did not decode or left bytes over.
    Decode,
}

impl PacketError {
    /// The link error reported back to the sender.
    pub fn link_error(&self) -> LinkError {
        match self {
            Self::Cobs(_) => LinkError::Cobs,
            Self::Overrun => LinkError::Overrun,
            Self::Short => LinkError::Short,
            Self::Crc { .. } => LinkError::Crc,
            Self::Decode => LinkError::Decode,
        }
    }
}

impl fmt::Display for PacketError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Cobs(e) => write!(f, "{e}"),
            Self::Overrun => f.write_str("packet longer than the receive buffer"),
            Self::Short => f.write_str("packet too short"),
            Self::Crc { stored, computed } => {
                write!(
                    f,
                    "CRC mismatch: stored {stored:08x}, computed {computed:08x}"
                )
            }
            Self::Decode => f.write_str("message does not decode"),
        }
    }
}

impl core::error::Error for PacketError {}

/// Build the un-stuffed packet (`seq`, message, CRC) into `out`; returns its length.
pub fn encode_packet(seq: u16, msg: &Message<'_>, out: &mut [u8]) -> Result<usize, EncodeError> {
    let body_max = out.len().min(MAX_PACKET_BYTES);
    let body = out.get_mut(..body_max).ok_or(EncodeError::TooLarge)?;
    let (head, rest) = body
        .split_at_mut_checked(SEQ_LEN)
        .ok_or(EncodeError::TooLarge)?;
    head.copy_from_slice(&seq.to_le_bytes());
    let room = rest.len().saturating_sub(CRC_LEN).min(MAX_MESSAGE_BYTES);
    let msg_len = postcard::to_slice(msg, rest.get_mut(..room).ok_or(EncodeError::TooLarge)?)
        .map_err(|_| EncodeError::TooLarge)?
        .len();
    let n = SEQ_LEN + msg_len;
    let crc = CRC32.checksum(body.get(..n).ok_or(EncodeError::TooLarge)?);
    body.get_mut(n..n + CRC_LEN)
        .ok_or(EncodeError::TooLarge)?
        .copy_from_slice(&crc.to_le_bytes());
    Ok(n + CRC_LEN)
}

/// Build the wire bytes (leading delimiter, COBS packet, trailing delimiter) into `out`;
/// `scratch` holds the un-stuffed packet and needs [`MAX_PACKET_BYTES`]. Returns the length.
pub fn encode_wire(
    seq: u16,
    msg: &Message<'_>,
    scratch: &mut [u8],
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let n = encode_packet(seq, msg, scratch)?;
    let body = scratch.get(..n).ok_or(EncodeError::TooLarge)?;
    *out.first_mut().ok_or(EncodeError::TooLarge)? = 0;
    let stuffed = out.get_mut(1..).ok_or(EncodeError::TooLarge)?;
    let m = cobs::encode(body, stuffed).map_err(|_| EncodeError::TooLarge)?;
    *out.get_mut(1 + m).ok_or(EncodeError::TooLarge)? = 0;
    Ok(m + 2)
}

/// Check and decode an un-stuffed packet; the message borrows from `packet`.
pub fn decode_packet(packet: &[u8]) -> Result<(u16, Message<'_>), PacketError> {
    if packet.len() < SEQ_LEN + CRC_LEN + 1 {
        return Err(PacketError::Short);
    }
    let (body, crc) = packet.split_at(packet.len() - CRC_LEN);
    let stored = crc
        .try_into()
        .map(u32::from_le_bytes)
        .map_err(|_| PacketError::Short)?;
    let computed = CRC32.checksum(body);
    if stored != computed {
        return Err(PacketError::Crc { stored, computed });
    }
    let (seq, msg) = body.split_at(SEQ_LEN);
    let seq = seq
        .try_into()
        .map(u16::from_le_bytes)
        .map_err(|_| PacketError::Short)?;
    let (msg, rest) = postcard::take_from_bytes(msg).map_err(|_| PacketError::Decode)?;
    if !rest.is_empty() {
        return Err(PacketError::Decode);
    }
    Ok((seq, msg))
}

/// Receives packets from a byte stream: COBS reassembly plus [`decode_packet`].
pub struct Receiver {
    acc: cobs::Accumulator<{ MAX_PACKET_BYTES + 8 }>,
}

impl Default for Receiver {
    fn default() -> Self {
        Self::new()
    }
}

/// What [`Receiver::push`] saw.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, PartialEq)]
pub enum Received<'a> {
    /// Nothing complete yet.
    Pending,
    /// A good packet.
    Packet(u16, Message<'a>),
    /// A delimited packet that failed.
    Error(PacketError),
}

impl Receiver {
    /// Empty receiver (`const`, so it can be a `static`).
    pub const fn new() -> Self {
        Self {
            acc: cobs::Accumulator::new(),
        }
    }
    /// Bytes of the packet in progress.
    pub fn pending(&self) -> usize {
        self.acc.pending()
    }
    /// Feed one byte.
    pub fn push(&mut self, byte: u8) -> Received<'_> {
        match self.acc.push(byte) {
            cobs::Fed::Pending => Received::Pending,
            cobs::Fed::Overrun { .. } => Received::Error(PacketError::Overrun),
            cobs::Fed::Bad(e) => Received::Error(PacketError::Cobs(e)),
            cobs::Fed::Packet(p) => match decode_packet(p) {
                Ok((seq, msg)) => Received::Packet(seq, msg),
                Err(e) => Received::Error(e),
            },
        }
    }
}
