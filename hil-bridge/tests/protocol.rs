//! Protocol: golden byte vectors (pinned in docs/hil-protocol.md), round trips of every
//! message, typed errors for corrupted bytes, and the target's link state machine driven
//! in-process through dropped, duplicated and corrupted bytes.

use hil_bridge::cobs;
use hil_bridge::msg::*;
use hil_bridge::packet::{
    MAX_CHUNK_BYTES, MAX_PACKET_BYTES, MAX_WIRE_BYTES, PacketError, decode_packet, encode_packet,
    encode_wire,
};
use hil_bridge::target::{Event, TargetInfo, TargetLink, payload_crc};
use hil_bridge::{PROTOCOL_VERSION, Received, Receiver};
use proptest::prelude::*;

fn wire(seq: u16, m: &Message<'_>) -> Vec<u8> {
    let mut s = [0u8; MAX_PACKET_BYTES];
    let mut w = [0u8; MAX_WIRE_BYTES];
    let n = encode_wire(seq, m, &mut s, &mut w).unwrap();
    w[..n].to_vec()
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).unwrap())
        .collect()
}

const CHUNK_DATA: [u8; 8] = [0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x20, 0xc1];

/// A confirmation frame's header (protocol v5's new job): a golden vector and a round trip.
fn confirm_header() -> Message<'static> {
    Message::FrameHeader(FrameHeader {
        frame_id: 14,
        width: 200,
        height: 200,
        pixel_m: 0.25,
        format: SampleFormat::HeightF32Le,
        payload_bytes: 160_000,
        payload_crc: 5,
        prior: None,
        job: FrameJob::Confirm([125.0, 115.0]),
    })
}

/// An atlas frame's header (protocol v6's new job, with its required prior).
fn atlas_header() -> Message<'static> {
    Message::FrameHeader(FrameHeader {
        frame_id: 15,
        width: 200,
        height: 200,
        pixel_m: 10.0,
        format: SampleFormat::HeightF32Le,
        payload_bytes: 160_000,
        payload_crc: 6,
        prior: Some(WirePrior {
            center_tile_px: [150.0, 150.0],
            sigma_px: 2.5,
            heading_rad: 0.5,
            heading_sigma_rad: 0.035,
            scale: 0.5,
            scale_sigma: 0.01,
        }),
        job: FrameJob::AtlasLocate,
    })
}

fn golden() -> Vec<(u16, Message<'static>, &'static str)> {
    vec![
        (
            0,
            Message::Hello(Hello {
                version: 1,
                session: 0x5EED_0001,
            }),
            "00 01 01 01 0b 01 81 80 b4 f7 05 2b 3d 4a a5 00",
        ),
        (
            1,
            Message::FrameChunk(FrameChunk {
                frame_id: 7,
                offset: 2048,
                data: &CHUNK_DATA,
            }),
            "00 02 01 06 03 07 80 10 08 01 03 80 3f 01 07 20 c1 2a a6 cb 08 00",
        ),
        (
            2,
            Message::FrameHeader(FrameHeader {
                frame_id: 7,
                width: 200,
                height: 200,
                pixel_m: 10.0,
                format: SampleFormat::HeightF32Le,
                payload_bytes: 160_000,
                payload_crc: 0xDEAD_BEEF,
                prior: None,
                job: FrameJob::Locate,
            }),
            "00 02 02 07 02 07 c8 01 c8 01 01 03 20 41 09 80 e2 09 ef fd b6 f5 0d 01 05 2a e0 df 8b 00",
        ),
        (
            3,
            Message::Ack(Ack { seq: 3 }),
            "00 02 03 07 04 03 4c e4 94 ce 00",
        ),
        (
            4,
            Message::Nack(Nack {
                expect_seq: 5,
                reason: NackReason::Link(LinkError::Crc),
            }),
            "00 02 04 03 05 05 06 03 d6 80 4f 82 00",
        ),
        (
            5,
            Message::FrameResult(hil_bridge::convert::refused(9, WireNavError::TooLarge)),
            "00 02 05 05 06 09 02 02 01 01 01 01 01 01 01 01 01 01 01 01 01 05 38 e7 b3 64 00",
        ),
        (6, Message::Shutdown, "00 02 06 06 0b 28 7c 1e 6c 00"),
        (
            8,
            atlas_header(),
            "00 02 08 07 02 0f c8 01 c8 01 01 03 20 41 06 80 e2 09 06 01 01 03 16 43 01 03 16 43 01 03 20 40 01 01 06 3f 29 5c 0f 3d 01 01 0b 3f 0a d7 23 3c 05 a1 5c fc 95 00",
        ),
        (
            9,
            Message::FrameResult(FrameResult {
                atlas: Some(WireAtlas {
                    tile: 3,
                    tile_offset_px: [105, 0],
                    candidates: 4,
                    tried: 2,
                    straddles: true,
                }),
                ..hil_bridge::convert::refused(10, WireNavError::OutsideAtlas)
            }),
            "00 02 09 05 06 0a 02 09 01 01 01 01 01 01 01 01 01 01 01 01 05 01 03 d2 01 08 04 02 01 19 e6 88 48 00",
        ),
        (
            7,
            confirm_header(),
            "00 02 07 07 02 0e c8 01 c8 01 01 03 80 3e 05 80 e2 09 05 02 04 01 03 fa 42 01 07 e6 42 4d ed 8f 34 00",
        ),
    ]
}

#[test]
fn golden_vectors_encode_and_decode() {
    assert_eq!(
        PROTOCOL_VERSION, 7,
        "a version bump needs new golden vectors"
    );
    for (seq, msg, bytes) in golden() {
        let expect = hex(bytes);
        assert_eq!(wire(seq, &msg), expect, "{msg:?}");
        let mut rx = Receiver::new();
        let mut got = None;
        for b in &expect {
            if let Received::Packet(s, m) = rx.push(*b) {
                got = Some((s, format!("{m:?}")));
            }
        }
        assert_eq!(got, Some((seq, format!("{msg:?}"))));
    }
}

fn sample_fix() -> WireFix {
    WireFix {
        affine: [0.5, -1e-3, 135.25, 1e-3, 0.5, 96.5],
        rotation_rad: 0.002,
        scale: 0.5000001,
        non_similar: 0.0085,
        center_tile_px: [185.7, 146.8],
        center_geo_m: [724.5, -54.25],
        heading_rad: 6.281,
        center_cov_tile_px2: [0.027, 0.0, -0.0, 0.027],
        center_cov_geo_m2: [10.8, 0.0, 0.0, 10.8],
        heading_sigma_rad: f64::MIN_POSITIVE,
        scale_sigma: 3e-3,
        inliers: 12,
        residual_rms_px: 0.73,
        refined: true,
        area_search: false,
    }
}

fn every_message() -> Vec<Message<'static>> {
    static DATA: [u8; MAX_CHUNK_BYTES] = [0xA5; MAX_CHUNK_BYTES];
    let result = FrameResult {
        frame_id: u32::MAX,
        outcome: WireOutcome::Fix(sample_fix()),
        features: 16,
        features_dropped: 3,
        matches: 13,
        inliers: 12,
        msac_iterations: 600,
        affine: Some(sample_fix().affine),
        match_stats: WireMatchStats {
            tile_candidates: 457,
            comparisons: 3656,
            rejected_ratio: 6,
            rejected_mutual: 1,
            dropped: 0,
        },
        offset: None,
        hazard: None,
        atlas: None,
    };
    // The largest result: an odometry fix with its offset (a hazard map comes in a result of
    // its own, but both together must fit too).
    let odometry = FrameResult {
        offset: Some(WireOffset {
            east_m: -12.25,
            north_m: 3.5e-3,
            cov_m2: [0.04, -1e-3, -1e-3, 0.05],
            footprint_m: 80.0,
            rotation_rad: -0.004,
            scale: 0.333_333_3,
        }),
        hazard: Some(WireHazard::Map(
            WireHazardStats {
                sites: 4096,
                safe: 1234,
                too_steep: 56,
                too_rough: 2800,
                no_data: 6,
                cols: 64,
                rows: 64,
                clearance_crc: 0x1234_5678,
            },
            WireAimDecision::Move(WireSafeSite {
                frame_px: [123.0, 87.0],
                clearance_m: 4.8,
                from_target_m: 11.8,
            }),
        )),
        atlas: Some(WireAtlas {
            tile: 4095,
            tile_offset_px: [-1, i32::MAX],
            candidates: 4,
            tried: 2,
            straddles: true,
        }),
        ..result
    };
    vec![
        Message::Hello(Hello {
            version: PROTOCOL_VERSION,
            session: 42,
        }),
        Message::HelloAck(HelloAck {
            version: PROTOCOL_VERSION,
            accepted: true,
            session: 42,
            tile_crc: 0xc26a_9007,
            tile_features: 457,
            max_frame_px: 40_000,
            max_frame_width: 200,
            max_chunk_bytes: MAX_CHUNK_BYTES as u16,
            atlas_crc: 0x80dd_cb9b,
            atlas_tiles: 16,
        }),
        Message::FrameHeader(FrameHeader {
            frame_id: 3,
            width: 200,
            height: 200,
            pixel_m: 10.0,
            format: SampleFormat::HeightF32Le,
            payload_bytes: 160_000,
            payload_crc: 1,
            prior: Some(WirePrior {
                center_tile_px: [150.0, -3.5],
                sigma_px: 8.0,
                heading_rad: 0.5,
                heading_sigma_rad: 0.1,
                scale: 0.5,
                scale_sigma: 0.02,
            }),
            job: FrameJob::Locate,
        }),
        Message::FrameChunk(FrameChunk {
            frame_id: 3,
            offset: 157_952,
            data: &DATA,
        }),
        Message::Ack(Ack { seq: u16::MAX }),
        Message::Nack(Nack {
            expect_seq: 0,
            reason: NackReason::Link(LinkError::SeqGap),
        }),
        Message::FrameResult(result),
        Message::FrameResult(FrameResult {
            outcome: WireOutcome::NoFix(WireNoFix::InconsistentWithPrior),
            affine: None,
            ..result
        }),
        Message::FrameResult(odometry),
        Message::FrameResult(FrameResult {
            outcome: WireOutcome::Keyframe(WireKeyframe {
                features: 16,
                tile_bytes: 25_080,
                tile_crc: 0xCAFE_F00D,
            }),
            ..hil_bridge::convert::refused(8, WireNavError::Empty)
        }),
        Message::FrameResult(FrameResult {
            outcome: WireOutcome::Hazard,
            hazard: Some(WireHazard::Refused(WireHazardError::TooFine)),
            ..hil_bridge::convert::refused(9, WireNavError::Empty)
        }),
        Message::FrameResult(hil_bridge::convert::refused(10, WireNavError::NoKeyframe)),
        Message::FrameHeader(FrameHeader {
            frame_id: 11,
            width: 200,
            height: 200,
            pixel_m: 0.4,
            format: SampleFormat::HeightF32Le,
            payload_bytes: 160_000,
            payload_crc: 2,
            prior: None,
            job: FrameJob::Odometry(WireOdometryPrior {
                offset_m: [3.2, -2.4],
                offset_cov_m2: [16.0, 0.0, 0.0, 16.0],
                heading_rad: 0.41,
                heading_sigma_rad: 0.0087,
                pixel_rel_sigma: 1e-3,
            }),
        }),
        Message::FrameHeader(FrameHeader {
            frame_id: 12,
            width: 200,
            height: 200,
            pixel_m: 0.6,
            format: SampleFormat::HeightF32Le,
            payload_bytes: 160_000,
            payload_crc: 3,
            prior: None,
            job: FrameJob::Keyframe(WireKeyframePose {
                heading_rad: 0.41,
                heading_sigma_rad: 0.0087,
                pixel_rel_sigma: 1e-3,
            }),
        }),
        Message::FrameHeader(FrameHeader {
            frame_id: 13,
            width: 200,
            height: 200,
            pixel_m: 0.4,
            format: SampleFormat::HeightF32Le,
            payload_bytes: 160_000,
            payload_crc: 4,
            prior: None,
            job: FrameJob::Hazard(WireAim {
                aim_px: [125.0, 115.0],
                target_px: [125.0, 115.0],
            }),
        }),
        confirm_header(),
        Message::FrameCost(FrameCost {
            frame_id: 3,
            window: 2,
            timer_cycles: 453_780,
            core_hz: 25_000_000,
            stack_peak_bytes: 14_620,
        }),
        Message::StatusRequest,
        Message::Status(Status {
            packets_ok: 1,
            duplicates: 2,
            cobs_errors: 3,
            overruns: 4,
            short_packets: 5,
            crc_errors: 6,
            decode_errors: 7,
            seq_gaps: 8,
            frames_done: 9,
            frames_aborted: 10,
        }),
        Message::Error(ErrorReport {
            code: ErrorCode::PayloadCrc,
            frame_id: 3,
        }),
        Message::Shutdown,
    ]
}

#[test]
fn every_message_round_trips_bit_for_bit() {
    for (i, m) in every_message().iter().enumerate() {
        let mut buf = [0u8; MAX_PACKET_BYTES];
        let n = encode_packet(i as u16, m, &mut buf).unwrap();
        let (seq, back) = decode_packet(&buf[..n]).unwrap();
        assert_eq!(seq, i as u16);
        assert_eq!(&back, m);
        // Floats survive bit for bit (compare the encodings, which hold the raw IEEE bytes).
        let again = postcard::to_stdvec(&back).unwrap();
        assert_eq!(again, postcard::to_stdvec(m).unwrap());
    }
}

#[test]
fn the_largest_messages_fit_the_buffers() {
    for m in every_message() {
        let n = postcard::to_stdvec(&m).unwrap().len();
        assert!(
            n <= hil_bridge::packet::MAX_MESSAGE_BYTES,
            "{n} bytes: {m:?}"
        );
        if !matches!(m, Message::FrameChunk(_)) {
            assert!(
                n + 6 <= hil_bridge::target::TX_PACKET_BYTES,
                "target message of {n} bytes"
            );
        }
    }
}

#[test]
fn corrupted_packets_give_typed_errors() {
    let good = wire(9, &Message::Ack(Ack { seq: 9 }));
    let feed = |bytes: &[u8]| -> Vec<Result<u16, PacketError>> {
        let mut rx = Receiver::new();
        let mut out = Vec::new();
        for b in bytes {
            match rx.push(*b) {
                Received::Pending => {}
                Received::Packet(s, _) => out.push(Ok(s)),
                Received::Error(e) => out.push(Err(e)),
            }
        }
        out
    };
    assert_eq!(feed(&good), vec![Ok(9)]);
    // A flipped payload byte: CRC mismatch.
    let mut flipped = good.clone();
    flipped[4] ^= 0x01;
    assert!(matches!(feed(&flipped)[..], [Err(PacketError::Crc { .. })]));
    // A dropped byte: the COBS structure or the CRC breaks.
    let mut dropped = good.clone();
    dropped.remove(3);
    assert!(matches!(
        feed(&dropped)[..],
        [Err(PacketError::Crc { .. } | PacketError::Cobs(_))]
    ));
    // A zero inside a packet splits it: two bad pieces, then the next packet is fine.
    let mut split = good.clone();
    split[5] = 0;
    split.extend_from_slice(&good);
    let r = feed(&split);
    assert_eq!(r.last(), Some(&Ok(9)));
    assert!(r[..r.len() - 1].iter().all(|x| x.is_err()));
    // Too short to hold a sequence number and a CRC.
    assert_eq!(decode_packet(&[1, 2, 3]), Err(PacketError::Short));
    // A good CRC over bytes that are not a message.
    let mut junk = vec![0u8, 0, 0xFF, 0xFF, 0xFF];
    let crc = hil_bridge::packet::CRC32.checksum(&junk);
    junk.extend_from_slice(&crc.to_le_bytes());
    assert_eq!(decode_packet(&junk), Err(PacketError::Decode));
    // Longer than the receive buffer: overrun at the delimiter, then resynchronised.
    let mut long = vec![0x05u8; MAX_PACKET_BYTES + 64];
    long.push(0);
    long.extend_from_slice(&good);
    assert_eq!(feed(&long), vec![Err(PacketError::Overrun), Ok(9)]);
}

/// Host side of an in-process session with the target state machine.
struct Harness {
    heights: Vec<f32>,
    replies: Vec<u8>,
}

impl Harness {
    fn new() -> Self {
        Self {
            heights: vec![0.0; 64 * 64],
            replies: Vec::new(),
        }
    }
}

fn info() -> TargetInfo {
    TargetInfo {
        tile_crc: 0x1234_5678,
        tile_features: 9,
        max_frame_width: 64,
        atlas_crc: 0,
        atlas_tiles: 0,
    }
}

fn decode_all(bytes: &[u8]) -> Vec<String> {
    let mut rx = Receiver::new();
    let mut out = Vec::new();
    for b in bytes {
        match rx.push(*b) {
            Received::Packet(_, m) => out.push(format!("{m:?}")),
            Received::Error(e) => out.push(format!("BAD {e}")),
            Received::Pending => {}
        }
    }
    out
}

fn frame_stream(frame_id: u32, payload: &[u8], first_seq: u16) -> Vec<Vec<u8>> {
    let header = FrameHeader {
        frame_id,
        width: 32,
        height: payload.len() as u16 / 128,
        pixel_m: 10.0,
        format: SampleFormat::HeightF32Le,
        payload_bytes: payload.len() as u32,
        payload_crc: payload_crc(payload),
        prior: None,
        job: FrameJob::Locate,
    };
    let mut v = vec![wire(first_seq, &Message::FrameHeader(header))];
    for (i, c) in payload.chunks(256).enumerate() {
        v.push(wire(
            first_seq + 1 + i as u16,
            &Message::FrameChunk(FrameChunk {
                frame_id,
                offset: (i * 256) as u32,
                data: c,
            }),
        ));
    }
    v
}

fn payload(rows: usize) -> (Vec<f32>, Vec<u8>) {
    let h: Vec<f32> = (0..32 * rows)
        .map(|i| (i as f32 * 0.37).sin() * 50.0)
        .collect();
    let b = h.iter().flat_map(|v| v.to_le_bytes()).collect();
    (h, b)
}

#[test]
fn target_assembles_a_clean_frame_exactly() {
    let mut hx = Harness::new();
    let (heights, bytes) = payload(16);
    let mut input = wire(
        0,
        &Message::Hello(Hello {
            version: PROTOCOL_VERSION,
            session: 5,
        }),
    );
    for p in frame_stream(11, &bytes, 1) {
        input.extend(p);
    }
    let mut link = TargetLink::new(info(), &mut hx.heights);
    let mut r: &[u8] = &input;
    let ev = link.poll(&mut r, &mut hx.replies).unwrap();
    let Event::Frame(f) = ev else {
        panic!("{ev:?}")
    };
    assert_eq!(f.header.frame_id, 11);
    assert_eq!(
        link.heights_m()
            .iter()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>(),
        heights.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!(
        link.poll(&mut r, &mut hx.replies).unwrap(),
        Event::EndOfStream
    );
    let replies = decode_all(&hx.replies);
    assert!(
        replies
            .iter()
            .any(|m| m.contains("HelloAck") && m.contains("accepted: true"))
    );
    assert_eq!(link.status().packets_ok, 1 + 1 + 8);
}

#[test]
fn wrong_version_is_refused() {
    let mut hx = Harness::new();
    let input = wire(
        0,
        &Message::Hello(Hello {
            version: 99,
            session: 5,
        }),
    );
    let (_, bytes) = payload(2);
    let mut all = input;
    for p in frame_stream(1, &bytes, 1) {
        all.extend(p);
    }
    let mut link = TargetLink::new(info(), &mut hx.heights);
    let mut r: &[u8] = &all;
    assert_eq!(
        link.poll(&mut r, &mut hx.replies).unwrap(),
        Event::EndOfStream
    );
    let replies = decode_all(&hx.replies);
    assert!(replies.iter().any(|m| m.contains("accepted: false")));
    assert!(replies.iter().any(|m| m.contains("VersionMismatch")));
    assert!(replies.iter().any(|m| m.contains("NoSession")));
}

/// Faults on the host → target stream never yield a frame with wrong data: the damaged packet is
/// NACKed, the resent one completes the frame, and the heights are exact.
#[test]
fn faults_are_rejected_and_recovered_never_a_corrupted_frame() {
    let (heights, bytes) = payload(16);
    type Fault = fn(&mut Vec<Vec<u8>>);
    let faults: [(&str, Fault); 5] = [
        ("corrupt", |p| p[3][6] ^= 0x40),
        ("drop byte", |p| {
            p[4].remove(7);
        }),
        ("duplicate byte", |p| {
            let b = p[2][5];
            p[2].insert(5, b);
        }),
        ("duplicate packet", |p| {
            let d = p[5].clone();
            p.insert(6, d);
        }),
        ("drop packet", |p| {
            p.remove(6);
        }),
    ];
    for (name, fault) in faults {
        let mut hx = Harness::new();
        let clean = frame_stream(2, &bytes, 1);
        let mut sent = clean.clone();
        fault(&mut sent);
        let mut link = TargetLink::new(info(), &mut hx.heights);
        let mut hello: &[u8] = &wire(
            0,
            &Message::Hello(Hello {
                version: PROTOCOL_VERSION,
                session: 1,
            }),
        );
        assert_eq!(
            link.poll(&mut hello, &mut hx.replies).unwrap(),
            Event::EndOfStream
        );
        // Stop-and-wait host: send each packet; on a NACK resend the packet the target expects.
        let mut frame = None;
        let mut i = 0usize;
        let mut resent = 0;
        let mut stream = sent.clone();
        while i < stream.len() {
            hx.replies.clear();
            let mut r: &[u8] = &stream[i];
            let ev = link.poll(&mut r, &mut hx.replies).unwrap();
            if let Event::Frame(f) = ev {
                frame = Some(f);
            }
            if let Some(nack) = decode_all(&hx.replies)
                .iter()
                .find(|m| m.starts_with("Nack"))
            {
                let expect: u16 = nack
                    .split("expect_seq: ")
                    .nth(1)
                    .and_then(|s| s.split(',').next())
                    .unwrap()
                    .parse()
                    .unwrap();
                // Resend from the expected packet with the clean bytes.
                stream = clean[(expect - 1) as usize..].to_vec();
                i = 0;
                resent += 1;
                continue;
            }
            i += 1;
        }
        let f = frame.unwrap_or_else(|| panic!("{name}: no frame"));
        assert_eq!(f.header.frame_id, 2);
        assert_eq!(
            link.heights_m()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            heights.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            "{name}"
        );
        let s = link.status();
        let rejected =
            s.crc_errors + s.cobs_errors + s.seq_gaps + s.short_packets + s.decode_errors;
        match name {
            "duplicate packet" => assert_eq!((s.duplicates, resent), (1, 0), "{name}: {s:?}"),
            _ => assert!(rejected >= 1 && resent >= 1, "{name}: {s:?}"),
        }
        assert_eq!(s.frames_done, 1, "{name}");
    }
}

#[test]
fn a_payload_crc_mismatch_aborts_the_frame() {
    let mut hx = Harness::new();
    let (_, bytes) = payload(4);
    let header = FrameHeader {
        frame_id: 4,
        width: 32,
        height: 4,
        pixel_m: 10.0,
        format: SampleFormat::HeightF32Le,
        payload_bytes: bytes.len() as u32,
        payload_crc: payload_crc(&bytes) ^ 1,
        prior: None,
        job: FrameJob::Locate,
    };
    let mut input = wire(
        0,
        &Message::Hello(Hello {
            version: PROTOCOL_VERSION,
            session: 1,
        }),
    );
    input.extend(wire(1, &Message::FrameHeader(header)));
    input.extend(wire(
        2,
        &Message::FrameChunk(FrameChunk {
            frame_id: 4,
            offset: 0,
            data: &bytes,
        }),
    ));
    let mut link = TargetLink::new(info(), &mut hx.heights);
    let mut r: &[u8] = &input;
    assert_eq!(
        link.poll(&mut r, &mut hx.replies).unwrap(),
        Event::EndOfStream
    );
    assert!(
        decode_all(&hx.replies)
            .iter()
            .any(|m| m.contains("PayloadCrc"))
    );
    assert_eq!(link.status().frames_aborted, 1);
    assert_eq!(link.status().frames_done, 0);
}

#[test]
fn oversized_and_out_of_order_frames_are_refused() {
    let mut hx = Harness::new();
    let big = FrameHeader {
        frame_id: 5,
        width: 65,
        height: 2,
        pixel_m: 10.0,
        format: SampleFormat::HeightF32Le,
        payload_bytes: 65 * 2 * 4,
        payload_crc: 0,
        prior: None,
        job: FrameJob::Locate,
    };
    let mut input = wire(
        0,
        &Message::Hello(Hello {
            version: PROTOCOL_VERSION,
            session: 1,
        }),
    );
    input.extend(wire(1, &Message::FrameHeader(big)));
    input.extend(wire(
        2,
        &Message::FrameChunk(FrameChunk {
            frame_id: 5,
            offset: 8,
            data: &[0; 8],
        }),
    ));
    let mut link = TargetLink::new(info(), &mut hx.heights);
    let mut r: &[u8] = &input;
    assert_eq!(
        link.poll(&mut r, &mut hx.replies).unwrap(),
        Event::EndOfStream
    );
    let replies = decode_all(&hx.replies);
    assert!(replies.iter().any(|m| m.contains("FrameTooLarge")));
    assert!(replies.iter().any(|m| m.contains("UnexpectedChunk")));
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        let mut rx = Receiver::new();
        for b in &bytes {
            let _ = rx.push(*b);
        }
        let _ = decode_packet(&bytes);
        let mut buf = bytes.clone();
        let _ = cobs::decode_in_place(&mut buf);
        let mut heights = vec![0.0f32; 256];
        let mut link = TargetLink::new(info(), &mut heights);
        let mut r: &[u8] = &bytes;
        let mut out = Vec::new();
        for _ in 0..8 {
            if link.poll(&mut r, &mut out).unwrap() == Event::EndOfStream {
                break;
            }
        }
    }

    #[test]
    fn cobs_round_trips(data in proptest::collection::vec(any::<u8>(), 0..2000)) {
        let mut enc = vec![0u8; cobs::max_encoded_len(data.len())];
        let n = cobs::encode(&data, &mut enc).unwrap();
        prop_assert!(!enc[..n].contains(&0));
        let m = cobs::decode_in_place(&mut enc[..n]).unwrap();
        prop_assert_eq!(&enc[..m], &data[..]);
    }

    #[test]
    fn chunks_round_trip(seq in any::<u16>(), id in any::<u32>(), off in any::<u32>(),
                         data in proptest::collection::vec(any::<u8>(), 0..MAX_CHUNK_BYTES)) {
        let m = Message::FrameChunk(FrameChunk { frame_id: id, offset: off, data: &data });
        let w = wire(seq, &m);
        prop_assert!(w.len() <= MAX_WIRE_BYTES);
        let mut rx = Receiver::new();
        let mut got = None;
        for b in &w {
            if let Received::Packet(s, back) = rx.push(*b) {
                got = Some((s, back == m));
            }
        }
        prop_assert_eq!(got, Some((seq, true)));
    }
}
