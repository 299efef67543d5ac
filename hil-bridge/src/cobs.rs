//! Consistent Overhead Byte Stuffing (Cheshire & Baker 1999): removes every `0x00` from a
//! packet so that `0x00` can delimit packets on a byte stream.
//!
//! Encoding splits the input at each zero into blocks; each block is written as a code byte
//! `1 + len` followed by its `len` non-zero bytes (`len ≤ 254`). A code of `0xFF` means 254 bytes
//! with no implied zero after them. The encoded length is at most
//! `len + len / 254 + 1` ([`max_encoded_len`]). The delimiter itself is not part of the encoding.

use core::fmt;

/// Why a COBS block could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CobsError {
    /// A zero byte inside an encoded packet (the stream lost a delimiter's context).
    ZeroInData,
    /// A code byte points past the end of the packet.
    Truncated,
    /// The output buffer is too small.
    Overflow,
}

impl fmt::Display for CobsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::ZeroInData => "COBS: zero byte inside a packet",
            Self::Truncated => "COBS: code byte runs past the end of the packet",
            Self::Overflow => "COBS: output buffer too small",
        })
    }
}

impl core::error::Error for CobsError {}

/// Largest encoded length of `len` input bytes (without the delimiter).
pub const fn max_encoded_len(len: usize) -> usize {
    len + len / 254 + 1
}

/// Encode `input` into `out`; returns the encoded length (no delimiter is written).
pub fn encode(input: &[u8], out: &mut [u8]) -> Result<usize, CobsError> {
    let mut code_at = 0usize;
    let mut w = 1usize;
    let mut code = 1u8;
    for &b in input {
        if b == 0 {
            *out.get_mut(code_at).ok_or(CobsError::Overflow)? = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            *out.get_mut(w).ok_or(CobsError::Overflow)? = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                *out.get_mut(code_at).ok_or(CobsError::Overflow)? = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    *out.get_mut(code_at).ok_or(CobsError::Overflow)? = code;
    Ok(w)
}

/// Decode one packet (without its delimiter) in place; returns the decoded length.
///
/// Decoding never writes ahead of reading, so the decoded bytes overwrite the front of `buf`.
pub fn decode_in_place(buf: &mut [u8]) -> Result<usize, CobsError> {
    let n = buf.len();
    let (mut r, mut w) = (0usize, 0usize);
    while r < n {
        let code = *buf.get(r).ok_or(CobsError::Truncated)?;
        if code == 0 {
            return Err(CobsError::ZeroInData);
        }
        r += 1;
        let run = code as usize - 1;
        if r + run > n {
            return Err(CobsError::Truncated);
        }
        for _ in 0..run {
            let b = *buf.get(r).ok_or(CobsError::Truncated)?;
            if b == 0 {
                return Err(CobsError::ZeroInData);
            }
            *buf.get_mut(w).ok_or(CobsError::Overflow)? = b;
            r += 1;
            w += 1;
        }
        // A block shorter than 254 bytes implies a zero, except at the very end of the packet.
        if code != 0xFF && r < n {
            *buf.get_mut(w).ok_or(CobsError::Overflow)? = 0;
            w += 1;
        }
    }
    Ok(w)
}

/// What [`Accumulator::push`] saw after one byte.
#[derive(Debug, PartialEq, Eq)]
pub enum Fed<'a> {
    /// More bytes are needed.
    Pending,
    /// A delimiter ended a complete packet: its decoded bytes.
    Packet(&'a [u8]),
    /// A delimiter ended a packet that does not decode.
    Bad(CobsError),
    /// A delimiter ended a packet longer than the buffer (its bytes were discarded).
    Overrun {
        /// Bytes seen before the delimiter.
        len: usize,
    },
}

/// Reassembles `0x00`-delimited COBS packets from a byte stream into a fixed buffer of `N` bytes.
///
/// Empty packets (two delimiters in a row) are skipped: senders may emit a leading delimiter to
/// flush any garbage the receiver holds. A packet longer than `N` is dropped whole and reported
/// at its delimiter, so the stream resynchronises on the next packet.
pub struct Accumulator<const N: usize> {
    buf: [u8; N],
    len: usize,
    overrun: bool,
}

impl<const N: usize> Default for Accumulator<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Accumulator<N> {
    /// Empty accumulator (`const`, so it can be a `static`).
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overrun: false,
        }
    }

    /// Forget a partial packet.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overrun = false;
    }

    /// Bytes of the packet in progress.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Feed one byte.
    pub fn push(&mut self, byte: u8) -> Fed<'_> {
        if byte != 0 {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = byte;
            } else {
                self.overrun = true;
            }
            self.len = self.len.saturating_add(1);
            return Fed::Pending;
        }
        let len = self.len;
        let overrun = self.overrun;
        self.reset();
        if overrun {
            return Fed::Overrun { len };
        }
        if len == 0 {
            return Fed::Pending;
        }
        let Some(packet) = self.buf.get_mut(..len) else {
            return Fed::Overrun { len };
        };
        match decode_in_place(packet) {
            Ok(n) => Fed::Packet(packet.get(..n).unwrap_or(&[])),
            Err(e) => Fed::Bad(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(data: &[u8]) {
        let mut enc = [0u8; 1200];
        let n = encode(data, &mut enc).unwrap();
        assert!(n <= max_encoded_len(data.len()));
        assert!(!enc[..n].contains(&0));
        let mut acc = Accumulator::<1200>::new();
        for &b in &enc[..n] {
            assert_eq!(acc.push(b), Fed::Pending);
        }
        match acc.push(0) {
            Fed::Packet(p) => assert_eq!(p, data),
            Fed::Pending if data.is_empty() => {}
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn known_vectors() {
        // From the COBS paper / Wikipedia examples.
        let cases: &[(&[u8], &[u8])] = &[
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x22, 0x33, 0x44], &[0x05, 0x11, 0x22, 0x33, 0x44]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, enc) in cases {
            let mut out = [0u8; 16];
            let n = encode(raw, &mut out).unwrap();
            assert_eq!(&out[..n], *enc);
            let mut buf = enc.to_vec();
            let m = decode_in_place(&mut buf).unwrap();
            assert_eq!(&buf[..m], *raw);
        }
    }

    #[test]
    fn long_runs_round_trip() {
        for len in [0usize, 1, 253, 254, 255, 508, 509, 1000] {
            let nonzero: std::vec::Vec<u8> = (0..len).map(|i| (i % 255 + 1) as u8).collect();
            round_trip(&nonzero);
            let mixed: std::vec::Vec<u8> = (0..len).map(|i| (i * 7 % 13) as u8).collect();
            round_trip(&mixed);
        }
    }

    #[test]
    fn overrun_is_reported_and_resynchronises() {
        let mut acc = Accumulator::<4>::new();
        for b in [1u8, 2, 3, 4, 5, 6] {
            assert_eq!(acc.push(b), Fed::Pending);
        }
        assert_eq!(acc.push(0), Fed::Overrun { len: 6 });
        for b in [0x03, 0x11, 0x22] {
            acc.push(b);
        }
        assert_eq!(acc.push(0), Fed::Packet(&[0x11, 0x22]));
    }

    #[test]
    fn truncated_code_is_an_error() {
        let mut acc = Accumulator::<8>::new();
        for b in [0x05, 0x11, 0x22] {
            acc.push(b);
        }
        assert_eq!(acc.push(0), Fed::Bad(CobsError::Truncated));
    }
}
