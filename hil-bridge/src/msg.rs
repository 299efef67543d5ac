//! Protocol messages. Each is postcard-encoded inside a packet (see [`crate::packet`]); the
//! enum variant index is the message's type byte on the wire. `docs/hil-protocol.md` has the
//! byte tables.
//!
//! Direction: **H→T** host to target, **T→H** target to host.

use serde::{Deserialize, Serialize};

/// Every message of protocol version [`crate::PROTOCOL_VERSION`]. Variant order is part of the
/// wire format: append only, and bump the version on any change.
///
/// Variants differ in size (a fix is ~200 bytes); without a heap there is nothing to box them
/// into, and messages live briefly on the stack.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Message<'a> {
    /// 0, H→T: open a session; the target answers [`Message::HelloAck`].
    Hello(Hello),
    /// 1, T→H: the target's version and capacities.
    HelloAck(HelloAck),
    /// 2, H→T: a frame follows in [`Message::FrameChunk`]s.
    FrameHeader(FrameHeader),
    /// 3, H→T: consecutive payload bytes of the frame being sent.
    #[serde(borrow)]
    FrameChunk(FrameChunk<'a>),
    /// 4, T→H: the packet with this sequence number was accepted.
    Ack(Ack),
    /// 5, T→H: a packet was rejected; resend from `expect_seq`.
    Nack(Nack),
    /// 6, T→H: what the navigator made of a frame.
    FrameResult(FrameResult),
    /// 7, T→H: what the frame cost on the target.
    FrameCost(FrameCost),
    /// 8, H→T: ask for [`Message::Status`].
    StatusRequest,
    /// 9, T→H: link and frame counters.
    Status(Status),
    /// 10, T→H: a request the target refused (not a link error).
    Error(ErrorReport),
    /// 11, H→T: end the session; the target answers [`Message::Status`] and stops.
    Shutdown,
}

/// Session opening (H→T).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Hello {
    /// The host's [`crate::PROTOCOL_VERSION`].
    pub version: u16,
    /// Session id chosen by the host (echoed in the acknowledgement).
    pub session: u32,
}

/// The target's answer to [`Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HelloAck {
    /// The target's [`crate::PROTOCOL_VERSION`].
    pub version: u16,
    /// Whether the target accepts the host's version (equal versions only).
    pub accepted: bool,
    /// Echo of [`Hello::session`].
    pub session: u32,
    /// CRC-32 stored in the reference tile linked into the target.
    pub tile_crc: u32,
    /// Features in that tile.
    pub tile_features: u32,
    /// Largest frame the target accepts, pixels (width × height).
    pub max_frame_px: u32,
    /// Widest frame the target accepts, pixels.
    pub max_frame_width: u16,
    /// Largest [`FrameChunk::data`] the target accepts, bytes.
    pub max_chunk_bytes: u16,
    /// CRC-32 stored at the end of the linked flight atlas's index (0: no atlas).
    pub atlas_crc: u32,
    /// Tiles in that atlas.
    pub atlas_tiles: u16,
}

/// How frame samples are encoded in the payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SampleFormat {
    /// DEM heights, metres, IEEE-754 `f32` little-endian, row-major (4 bytes per pixel).
    HeightF32Le,
}

/// Predicted pose sent with a frame (mirrors `nav_core::Prior`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WirePrior {
    /// Predicted frame centre, tile pixels `[x, y]`.
    pub center_tile_px: [f32; 2],
    /// 1σ position uncertainty, tile pixels.
    pub sigma_px: f32,
    /// Predicted heading, radians.
    pub heading_rad: f32,
    /// 1σ heading uncertainty, radians.
    pub heading_sigma_rad: f32,
    /// Predicted scale, tile pixels per frame pixel.
    pub scale: f32,
    /// 1σ scale uncertainty.
    pub scale_sigma: f32,
}

/// Announces a frame (H→T). A new header aborts any frame still being assembled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameHeader {
    /// Frame id chosen by the host; results carry it back.
    pub frame_id: u32,
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Ground sample distance, metres per pixel.
    pub pixel_m: f32,
    /// Sample encoding of the payload.
    pub format: SampleFormat,
    /// Payload length, bytes (`width × height × 4` for [`SampleFormat::HeightF32Le`]).
    pub payload_bytes: u32,
    /// CRC-32 (ISO-HDLC) of the whole payload: end-to-end check over the reassembled frame.
    pub payload_crc: u32,
    /// Optional predicted pose (used by [`FrameJob::Locate`]).
    pub prior: Option<WirePrior>,
    /// What the target does with the frame.
    pub job: FrameJob,
}

/// What the target does with a frame: the five frame jobs of a descent. Every job runs
/// the flight code of `nav_core` with the flight configuration, as the descent does.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameJob {
    /// 0: terrain-relative navigation on the reference tile, with the header's prior if any.
    Locate,
    /// 1: make this frame the keyframe (`nav_core::odometry::Keyframe::capture`); the
    /// keyframe's pixel is the header's `pixel_m`.
    Keyframe(WireKeyframePose),
    /// 2: locate the frame on the keyframe held by the target
    /// (`nav_core::odometry::locate_on_keyframe`), the prior made on the target by
    /// `Keyframe::prior` from the filter's prediction below.
    Odometry(WireOdometryPrior),
    /// 3: build the hazard map from the frame (`nav_core::hazard::HazardMap::build`, flight
    /// `HazardConfig`) and decide the aim (`HazardMap::decide`). A frame of its own: the
    /// descent spends one frame on the map, not on odometry.
    Hazard(WireAim),
    /// 4: confirm the chosen aim on a finer frame: the hazard map of the window around it
    /// (`nav_core::hazard::HazardMap::build_around`, `HazardConfig::confirmation`,
    /// `CONFIRM_HALF_WINDOW_M`) and its decision with the aim as its own target. The aim, frame
    /// pixels `[x, y]`.
    Confirm([f32; 2]),
    /// 5: terrain-relative navigation on the linked flight atlas
    /// (`nav_core::atlas::AtlasNavigator::locate_dem`, flight `AtlasConfig`): the header's
    /// prior, in atlas pixels, is required (it picks the tile). The fix comes in the pixels of
    /// the tile named in [`FrameResult::atlas`].
    AtlasLocate,
}

/// Where guidance aims and the planned target, frame pixels `[x, y]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireAim {
    /// The current aim.
    pub aim_px: [f32; 2],
    /// The planned landing target.
    pub target_px: [f32; 2],
}

/// The filter's knowledge at keyframe capture (mirrors `nav_core::odometry::KeyframePose`; the
/// pixel size is the header's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireKeyframePose {
    /// Frame +x axis, clockwise from east, radians.
    pub heading_rad: f64,
    /// 1σ of the heading, radians.
    pub heading_sigma_rad: f64,
    /// Relative 1σ of the pixel size.
    pub pixel_rel_sigma: f64,
}

/// The filter's prediction for an odometry frame (the arguments of
/// `nav_core::odometry::Keyframe::prior`; the frame pixel is the header's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireOdometryPrior {
    /// Predicted displacement since the keyframe, metres `[east, north]`.
    pub offset_m: [f64; 2],
    /// Its covariance, m², row-major.
    pub offset_cov_m2: [f64; 4],
    /// Predicted frame +x axis, clockwise from east, radians.
    pub heading_rad: f64,
    /// 1σ of the heading, radians.
    pub heading_sigma_rad: f64,
    /// Relative 1σ of the pixel size.
    pub pixel_rel_sigma: f64,
}

/// Consecutive payload bytes (H→T). Chunks must arrive in order without gaps.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameChunk<'a> {
    /// Frame this chunk belongs to.
    pub frame_id: u32,
    /// Byte offset of `data` in the payload.
    pub offset: u32,
    /// The bytes (borrowed from the packet: no copy on decode).
    pub data: &'a [u8],
}

/// Packet accepted (T→H).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ack {
    /// Sequence number of the accepted packet.
    pub seq: u16,
}

/// Link-level reasons for rejecting bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LinkError {
    /// The packet does not COBS-decode.
    Cobs,
    /// The packet is longer than the receive buffer.
    Overrun,
    /// Shorter than a sequence number and a CRC.
    Short,
    /// CRC-32 mismatch.
    Crc,
    /// CRC good but the message does not decode (or has trailing bytes).
    Decode,
    /// Sequence number ahead of the expected one: packets were lost.
    SeqGap,
}

/// Packet rejected (T→H): the host resends starting with sequence number `expect_seq`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NackReason {
    /// Bytes that were not a valid packet.
    Link(LinkError),
}

/// Packet rejected (T→H).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Nack {
    /// The sequence number the target expects next.
    pub expect_seq: u16,
    /// Why.
    pub reason: NackReason,
}

/// Affine map frame px → tile px, `[m1, n1, p1, m2, n2, p2]` (nav-core's eq 18 order).
pub type WireAffine = [f64; 6];

/// A navigation fix (mirrors `nav_core::Fix`, every `f64` bit for bit, but for
/// `map_noise_power_m4`, the tile's own figure, which only the ground's filter uses).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireFix {
    /// Frame px → tile px.
    pub affine: WireAffine,
    /// Rotation φ, radians.
    pub rotation_rad: f64,
    /// Scale s, tile px per frame px.
    pub scale: f64,
    /// Departure of the least-squares affine from a similarity.
    pub non_similar: f64,
    /// Frame centre, tile px `[x, y]`.
    pub center_tile_px: [f64; 2],
    /// Frame centre, geo metres `[x, y]`.
    pub center_geo_m: [f64; 2],
    /// Heading, radians in [0, 2π).
    pub heading_rad: f64,
    /// Covariance of the centre, tile px², row-major.
    pub center_cov_tile_px2: [f64; 4],
    /// Covariance of the centre, m², row-major.
    pub center_cov_geo_m2: [f64; 4],
    /// Heading σ, radians.
    pub heading_sigma_rad: f64,
    /// Scale σ.
    pub scale_sigma: f64,
    /// Inliers used.
    pub inliers: u16,
    /// RMS transfer error of the inliers, tile px.
    pub residual_rms_px: f64,
    /// The transform comes from the dense refinement over the frame's pixels.
    pub refined: bool,
    /// The fix comes from the prior-aided area search, not from feature matches.
    pub area_search: bool,
}

/// Why there is no fix (mirrors `nav_core::NoFix`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireNoFix {
    /// Too few features.
    TooFewFeatures,
    /// Too few putative matches.
    TooFewMatches,
    /// No consensus.
    TooFewInliers,
    /// Inliers collinear or clustered.
    DegenerateGeometry,
    /// Far from a similarity.
    NonSimilar,
    /// Scale out of range.
    ScaleOutOfRange,
    /// Residual too large.
    ResidualTooLarge,
    /// Inconsistent with the prior.
    InconsistentWithPrior,
    /// Not confirmed (or contradicted) by the dense slope correlation.
    Unconfirmed,
    /// The frame's work budget had no room for the stage that could have fixed it.
    OverBudget,
}

/// Why the navigator refused a frame outright (mirrors `nav_core::NavError`, flattened).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireNavError {
    /// Zero width or height.
    Empty,
    /// Buffer length disagrees with the size.
    SizeMismatch,
    /// Larger than the workspace.
    TooLarge,
    /// Pixel size not finite or ≤ 0.
    BadPixelSize,
    /// SURF configuration out of range.
    SurfConfig,
    /// A keyframe pose or odometry prior input not finite or out of range.
    BadPose,
    /// An odometry frame before any keyframe was captured.
    NoKeyframe,
    /// The keyframe tile could not be written or read back.
    KeyframeTile,
    /// An atlas job without an atlas linked, without a prior, or on a tile that does not read.
    Atlas,
    /// An atlas job whose prior no tile of the atlas reaches.
    OutsideAtlas,
}

/// Which atlas tile a [`FrameJob::AtlasLocate`] frame was located on (mirrors
/// `nav_core::atlas::AtlasReport`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireAtlas {
    /// The tile whose report this is (the first that fixed, else the first tried).
    pub tile: u16,
    /// Atlas pixel of that tile's pixel (0, 0) `[col, row]`: add it to the fix's tile pixels.
    pub tile_offset_px: [i32; 2],
    /// Tiles ranked for the frame.
    pub candidates: u8,
    /// Tiles located on.
    pub tried: u8,
    /// No tile held the frame's whole reach.
    pub straddles: bool,
}

/// A captured keyframe (T→H, in [`WireOutcome::Keyframe`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireKeyframe {
    /// SURF features in the keyframe tile.
    pub features: u16,
    /// Keyframe tile blob, bytes.
    pub tile_bytes: u32,
    /// CRC-32 stored in the keyframe tile (covers features and raster: a bit-exact digest).
    pub tile_crc: u32,
}

/// Displacement since the keyframe (mirrors `nav_core::odometry::OffsetFix`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireOffset {
    /// East, metres.
    pub east_m: f64,
    /// North, metres.
    pub north_m: f64,
    /// Covariance, m², row-major (east, north).
    pub cov_m2: [f64; 4],
    /// Frame footprint, metres.
    pub footprint_m: f64,
    /// Rotation of the frame on the keyframe, radians.
    pub rotation_rad: f64,
    /// Scale, keyframe raster px per frame px.
    pub scale: f64,
}

/// The chosen safe site (mirrors `nav_core::hazard::SafeSite`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireSafeSite {
    /// Position, frame pixels `[x, y]`.
    pub frame_px: [f32; 2],
    /// Clearance, metres.
    pub clearance_m: f32,
    /// Distance from the target, metres.
    pub from_target_m: f32,
}

/// A hazard map (T→H): its counts, a digest of every site's clearance, the chosen site.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireHazardStats {
    /// Sites judged.
    pub sites: u32,
    /// Safe sites.
    pub safe: u32,
    /// Too steep.
    pub too_steep: u32,
    /// Too rough (relief alone).
    pub too_rough: u32,
    /// No data under the footprint.
    pub no_data: u32,
    /// Lattice columns.
    pub cols: u16,
    /// Lattice rows.
    pub rows: u16,
    /// CRC-32 (ISO-HDLC) of every site's clearance (`f32` metres, little-endian, row-major):
    /// the whole map, bit for bit, in four bytes.
    pub clearance_crc: u32,
}

/// What the hazard step made of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireHazard {
    /// 0: a map, and its decision for the aim.
    Map(WireHazardStats, WireAimDecision),
    /// 1: no map (mirrors `nav_core::hazard::HazardError`).
    Refused(WireHazardError),
}

/// A map's decision for the aim (mirrors `nav_core::hazard::AimDecision`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireAimDecision {
    /// 0: keep the aim; its clearance, m.
    Keep(f32),
    /// 1: fly to this site.
    Move(WireSafeSite),
    /// 2: nothing within reach qualifies.
    NoSite,
}

/// Why no hazard map was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireHazardError {
    /// Settings not finite or not positive.
    BadConfig,
    /// Frame pixels too coarse for the footprint.
    TooCoarse,
    /// Frame pixels too fine for the footprint window.
    TooFine,
    /// Frame smaller than one footprint.
    TooSmall,
    /// More sites than the map holds.
    TooManySites,
    /// The confirmation window holds no site of the frame.
    WindowOutside,
}

/// Outcome of one frame.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WireOutcome {
    /// A fix.
    Fix(WireFix),
    /// A typed no-fix.
    NoFix(WireNoFix),
    /// The frame was refused before navigation.
    Refused(WireNavError),
    /// The frame became the keyframe ([`FrameJob::Keyframe`]).
    Keyframe(WireKeyframe),
    /// The frame was mapped for hazards ([`FrameJob::Hazard`]; the map is in
    /// [`FrameResult::hazard`]).
    Hazard,
}

/// Matching counters (mirrors `nav_core::matching::MatchStats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireMatchStats {
    /// Tile features considered.
    pub tile_candidates: u32,
    /// Descriptor comparisons started.
    pub comparisons: u32,
    /// Refused by the ratio test.
    pub rejected_ratio: u32,
    /// Refused by the mutual check.
    pub rejected_mutual: u32,
    /// Dropped because the match list was full.
    pub dropped: u32,
}

/// Everything one frame produced (mirrors `nav_core::FrameReport`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameResult {
    /// Frame id from the header.
    pub frame_id: u32,
    /// Fix, no-fix or refusal.
    pub outcome: WireOutcome,
    /// Frame features extracted.
    pub features: u16,
    /// Keypoints dropped by the budget.
    pub features_dropped: u32,
    /// Putative matches.
    pub matches: u16,
    /// MSAC inliers.
    pub inliers: u16,
    /// MSAC samples drawn.
    pub msac_iterations: u16,
    /// The MSAC affine, if MSAC ran.
    pub affine: Option<WireAffine>,
    /// Matching counters.
    pub match_stats: WireMatchStats,
    /// The displacement since the keyframe, for an odometry fix.
    pub offset: Option<WireOffset>,
    /// The hazard map, for [`FrameJob::Hazard`].
    pub hazard: Option<WireHazard>,
    /// The atlas tile, for [`FrameJob::AtlasLocate`].
    pub atlas: Option<WireAtlas>,
}

/// What one frame cost on the target (T→H), sent before its [`FrameResult`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameCost {
    /// Frame id.
    pub frame_id: u32,
    /// Index of the navigation window (0-based count of `locate` calls since reset): the host
    /// pairs it with the instruction counter's record of the same window.
    pub window: u32,
    /// Core-clock cycles from the target's own timer (SysTick; a flight board would use DWT).
    /// Under QEMU with `-icount shift=0` this is deterministic but coarse.
    pub timer_cycles: u32,
    /// Core clock of `timer_cycles`, Hz.
    pub core_hz: u32,
    /// Deepest stack use seen so far, bytes (stack painted at reset).
    pub stack_peak_bytes: u32,
}

/// Link and frame counters (T→H). All counters saturate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Packets accepted.
    pub packets_ok: u32,
    /// Duplicated packets (sequence number already accepted): acknowledged, not acted on.
    pub duplicates: u32,
    /// Packets that did not COBS-decode.
    pub cobs_errors: u32,
    /// Packets longer than the receive buffer.
    pub overruns: u32,
    /// Packets shorter than a sequence number and a CRC.
    pub short_packets: u32,
    /// CRC-32 mismatches.
    pub crc_errors: u32,
    /// Messages that did not decode.
    pub decode_errors: u32,
    /// Packets that arrived after a gap in sequence numbers.
    pub seq_gaps: u32,
    /// Frames assembled and navigated.
    pub frames_done: u32,
    /// Frames abandoned (new header, bad chunk, payload CRC mismatch, refused header).
    pub frames_aborted: u32,
}

/// Requests the target refuses (T→H), beside link errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// The host's protocol version differs from the target's.
    VersionMismatch,
    /// A request before a successful hello.
    NoSession,
    /// Frame larger than the target's buffers.
    FrameTooLarge,
    /// `payload_bytes` disagrees with the size and format.
    BadFrameHeader,
    /// A chunk for another frame, out of order, or past the payload's end.
    UnexpectedChunk,
    /// The reassembled payload fails its CRC.
    PayloadCrc,
    /// A message only the target sends.
    WrongDirection,
}

/// A refused request (T→H).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ErrorReport {
    /// What went wrong.
    pub code: ErrorCode,
    /// The frame concerned (0 if none).
    pub frame_id: u32,
}
