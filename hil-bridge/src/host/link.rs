//! The host's side of the link: stop-and-wait sending with resend on NACK or timeout, a reader
//! thread decoding the target's packets, and deterministic fault injection.

use crate::msg::{Message, Status};
use crate::packet::{MAX_PACKET_BYTES, MAX_WIRE_BYTES, Received, Receiver, encode_wire};
use anyhow::{Context, Result, bail};
use std::io::{Read, Write};
use std::sync::mpsc::{Receiver as Rx, RecvTimeoutError, Sender};
use std::time::{Duration, Instant};

/// A fault injected into one packet on its way to the target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// One byte inside the packet XOR-ed with a non-zero value.
    CorruptByte,
    /// One byte inside the packet left out.
    DropByte,
    /// One byte inside the packet sent twice.
    DuplicateByte,
    /// The whole packet sent twice.
    DuplicatePacket,
    /// The whole packet never sent (recovered by the timeout).
    DropPacket,
}

impl Fault {
    /// Every kind, in the order the runner cycles through them.
    pub const ALL: [Fault; 5] = [
        Fault::CorruptByte,
        Fault::DropByte,
        Fault::DuplicateByte,
        Fault::DuplicatePacket,
        Fault::DropPacket,
    ];
}

/// Apply `fault` to the wire bytes of one packet (`00 · COBS · 00`); `pick` chooses the byte.
pub fn inject(fault: Fault, wire: &[u8], pick: usize) -> Vec<u8> {
    // Bytes strictly inside the COBS body, so the delimiters survive.
    let inner = 1 + pick % wire.len().saturating_sub(2).max(1);
    let mut out = wire.to_vec();
    match fault {
        Fault::CorruptByte => {
            let v = out[inner] ^ 0x5A;
            // A zero would split the packet in two: still detected, but keep the fault single.
            out[inner] = if v == 0 { 0xA5 } else { v };
        }
        Fault::DropByte => {
            out.remove(inner);
        }
        Fault::DuplicateByte => out.insert(inner, wire[inner]),
        Fault::DuplicatePacket => out.extend_from_slice(wire),
        Fault::DropPacket => out.clear(),
    }
    out
}

/// A decoded target → host message (the target never sends borrowed data).
pub type Reply = Message<'static>;

fn to_owned(m: &Message<'_>) -> Option<Reply> {
    Some(match *m {
        Message::Hello(x) => Message::Hello(x),
        Message::HelloAck(x) => Message::HelloAck(x),
        Message::FrameHeader(x) => Message::FrameHeader(x),
        Message::FrameChunk(_) => return None,
        Message::Ack(x) => Message::Ack(x),
        Message::Nack(x) => Message::Nack(x),
        Message::FrameResult(x) => Message::FrameResult(x),
        Message::FrameCost(x) => Message::FrameCost(x),
        Message::StatusRequest => Message::StatusRequest,
        Message::Status(x) => Message::Status(x),
        Message::Error(x) => Message::Error(x),
        Message::Shutdown => Message::Shutdown,
    })
}

/// What the reader thread delivers.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum Incoming {
    /// A good packet.
    Msg(u16, Reply),
    /// Bytes from the target that were not a packet (a T→H link error).
    Bad(crate::packet::PacketError),
    /// The stream ended.
    Closed,
}

/// Decode the target's byte stream on a thread of its own.
pub fn spawn_reader(mut r: impl Read + Send + 'static, tx: Sender<Incoming>) {
    std::thread::spawn(move || {
        let mut rx = Receiver::new();
        let mut buf = [0u8; 4096];
        loop {
            let n = match r.read(&mut buf) {
                Ok(0) | Err(_) => {
                    let _ = tx.send(Incoming::Closed);
                    return;
                }
                Ok(n) => n,
            };
            for &b in &buf[..n] {
                let item = match rx.push(b) {
                    Received::Pending => continue,
                    Received::Error(e) => Incoming::Bad(e),
                    Received::Packet(seq, m) => match to_owned(&m) {
                        Some(m) => Incoming::Msg(seq, m),
                        None => continue,
                    },
                };
                if tx.send(item).is_err() {
                    return;
                }
            }
        }
    });
}

/// Link counters on the host side.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct HostCounters {
    /// Packets sent (first attempts).
    pub packets: u64,
    /// Packets resent after a NACK.
    pub resent_after_nack: u64,
    /// Packets resent after a timeout.
    pub resent_after_timeout: u64,
    /// Faults injected.
    pub faults_injected: u64,
    /// Injected faults after which the packet was delivered and acknowledged.
    pub faults_recovered: u64,
    /// Bad packets from the target.
    pub bad_replies: u64,
    /// Gaps in the target's sequence numbers.
    pub reply_seq_gaps: u64,
}

/// The host end of a session.
pub struct HostLink<W: Write> {
    w: W,
    rx: Rx<Incoming>,
    seq: u16,
    next_reply_seq: Option<u16>,
    /// Messages other than ACK/NACK, in arrival order.
    pub inbox: std::collections::VecDeque<Reply>,
    /// Counters.
    pub counters: HostCounters,
    /// How long to wait for an acknowledgement before resending.
    pub ack_timeout: Duration,
}

impl<W: Write> HostLink<W> {
    /// A link writing to `w` and reading decoded replies from `rx`.
    pub fn new(w: W, rx: Rx<Incoming>) -> Self {
        Self {
            w,
            rx,
            seq: 0,
            next_reply_seq: None,
            inbox: Default::default(),
            counters: HostCounters::default(),
            ack_timeout: Duration::from_millis(1500),
        }
    }

    fn take(&mut self, timeout: Duration) -> Result<Option<Reply>> {
        match self.rx.recv_timeout(timeout) {
            Ok(Incoming::Msg(seq, m)) => {
                if let Some(want) = self.next_reply_seq
                    && seq != want
                {
                    self.counters.reply_seq_gaps += 1;
                }
                self.next_reply_seq = Some(seq.wrapping_add(1));
                Ok(Some(m))
            }
            Ok(Incoming::Bad(_)) => {
                self.counters.bad_replies += 1;
                Ok(None)
            }
            Ok(Incoming::Closed) => bail!("the target closed the link"),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => bail!("link reader stopped"),
        }
    }

    /// Send `msg` and wait for its ACK, resending on NACK or timeout. `fault` is applied to the
    /// first attempt only.
    pub fn send(&mut self, msg: &Message<'_>, fault: Option<(Fault, usize)>) -> Result<()> {
        let mut scratch = [0u8; MAX_PACKET_BYTES];
        let mut wire = [0u8; MAX_WIRE_BYTES];
        let seq = self.seq;
        let n = encode_wire(seq, msg, &mut scratch, &mut wire).context("encode")?;
        let clean = &wire[..n];
        self.counters.packets += 1;
        let first = match fault {
            Some((f, pick)) => {
                self.counters.faults_injected += 1;
                inject(f, clean, pick)
            }
            None => clean.to_vec(),
        };
        self.w.write_all(&first)?;
        self.w.flush()?;
        let mut attempts = 1;
        loop {
            let deadline = Instant::now() + self.ack_timeout;
            let mut resend = false;
            while !resend {
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    self.counters.resent_after_timeout += 1;
                    break;
                }
                match self.take(left)? {
                    Some(Message::Ack(a)) if a.seq == seq => {
                        self.seq = seq.wrapping_add(1);
                        if fault.is_some() {
                            self.counters.faults_recovered += 1;
                        }
                        return Ok(());
                    }
                    Some(Message::Nack(k)) if k.expect_seq == seq => {
                        self.counters.resent_after_nack += 1;
                        resend = true;
                    }
                    Some(Message::Ack(_)) | Some(Message::Nack(_)) | None => {}
                    Some(other) => self.inbox.push_back(other),
                }
            }
            attempts += 1;
            if attempts > 20 {
                bail!("packet {seq} not acknowledged after 20 attempts");
            }
            self.w.write_all(clean)?;
            self.w.flush()?;
        }
    }

    /// Wait up to `timeout` for a message matching `want` (others stay in the inbox).
    pub fn wait_for(
        &mut self,
        timeout: Duration,
        mut want: impl FnMut(&Reply) -> bool,
    ) -> Result<Reply> {
        if let Some(i) = self.inbox.iter().position(&mut want)
            && let Some(m) = self.inbox.remove(i)
        {
            return Ok(m);
        }
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                bail!("timed out waiting for the target");
            }
            match self.take(left)? {
                Some(m) if want(&m) => return Ok(m),
                Some(Message::Ack(_)) | Some(Message::Nack(_)) | None => {}
                Some(m) => self.inbox.push_back(m),
            }
        }
    }

    /// Ask for the target's counters.
    pub fn status(&mut self) -> Result<Status> {
        self.send(&Message::StatusRequest, None)?;
        match self.wait_for(Duration::from_secs(30), |m| matches!(m, Message::Status(_)))? {
            Message::Status(s) => Ok(s),
            _ => bail!("unexpected reply"),
        }
    }
}
