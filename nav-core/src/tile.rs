//! Reference tile: a versioned, checksummed, little-endian blob of SURF features with its
//! geo-reference, read in place (from flash) without copying or allocating.
//!
//! Layout (all integers and floats little-endian; the prose spec with byte tables is
//! `docs/tile-format.md`):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 8 | magic `UMBRATIL` |
//! | 8 | 2 | format version ([`TILE_FORMAT_VERSION`]) |
//! | 10 | 2 | header length `H` in bytes |
//! | 12 | 4 | feature count `N` |
//! | 16 | 4 | slope raster pixels `R`: 0 (none) or width × height |
//! | 20 | H | header, postcard-encoded [`TileHeader`] |
//! | 20 + H | pad | zeros up to a multiple of 4 |
//! | K | 24·N | keypoints ([`KEYPOINT_RECORD_LEN`] bytes each) |
//! | K + 24·N | 256·N | descriptors (64 × `f32` each) |
//! | K + 280·N | 2·R, padded to 4 | reference slope raster (raw [`SlopePx`], row-major) |
//! | end − 4 | 4 | CRC-32 (ISO-HDLC, as zlib) of every byte before it |

use crate::describe::{DESCRIPTOR_LEN, Descriptor};
use crate::detector::{DetectorConfig, Keypoint};
use crate::frame::{SLOPE_NODATA, SlopePx};
use crate::surf::{Feature, SurfConfig};
use core::fmt;
use serde::{Deserialize, Serialize};

/// Magic bytes at offset 0.
pub const TILE_MAGIC: [u8; 8] = *b"UMBRATIL";
/// Format version this code reads and writes.
pub const TILE_FORMAT_VERSION: u16 = 5;
/// Bytes before the header.
pub const PREAMBLE_LEN: usize = 20;
/// Most raster pixels a tile may hold (a 16 384² map; 512 MiB, far beyond any flash).
pub const MAX_RASTER_PX: usize = 1 << 28;
/// Bytes per keypoint record: x, y, scale, orientation, response (`f32`), flags (`u32`).
pub const KEYPOINT_RECORD_LEN: usize = 24;
/// Bytes per descriptor.
pub const DESCRIPTOR_RECORD_LEN: usize = 4 * DESCRIPTOR_LEN;
/// Largest header accepted, bytes (the projection note is the only variable part).
pub const MAX_HEADER_LEN: usize = 512;
/// Longest projection note, bytes of UTF-8.
pub const MAX_PROJECTION_LEN: usize = 256;
/// Most features a tile may hold (indices are `u16` in match lists).
pub const MAX_TILE_FEATURES: usize = 65_535;
/// Flag bit: Laplacian sign positive.
const FLAG_LAPLACIAN_POSITIVE: u32 = 1;

const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Geo-reference and provenance of a tile.
///
/// Geo coordinates of the centre of tile pixel `(col, row)`:
/// `x_m = origin_x_m + col · pixel_x_m`, `y_m = origin_y_m + row · pixel_y_m` (for a north-up
/// map `pixel_y_m` is negative). Units are metres of the projection named in `projection`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TileHeader<'a> {
    /// Tile width in pixels.
    pub width_px: u32,
    /// Tile height in pixels.
    pub height_px: u32,
    /// Geo x of the centre of pixel (0, 0), metres.
    pub origin_x_m: f64,
    /// Geo y of the centre of pixel (0, 0), metres.
    pub origin_y_m: f64,
    /// Geo x step per column, metres.
    pub pixel_x_m: f64,
    /// Geo y step per row, metres (negative for north-up).
    pub pixel_y_m: f64,
    /// Free-text projection note (e.g. a PROJ string or EPSG code), at most
    /// [`MAX_PROJECTION_LEN`] bytes.
    pub projection: &'a str,
    /// Number of features (must equal the preamble's count).
    pub feature_count: u32,
    /// Detector octaves used for the tile.
    pub octaves: u8,
    /// Detector layers per octave.
    pub layers: u8,
    /// Detector threshold, (degrees of slope)².
    pub threshold: f32,
    /// Smallest keypoint scale kept, tile pixels.
    pub min_scale_px: f32,
    /// Whether orientations were assigned (false) or all zero (upright).
    pub upright: bool,
    /// Resolution of the terrain the features were detected on: the standard deviation, metres,
    /// of the Gaussian the reference DEM carries on top of its pixel averaging (smoothing
    /// applied by the tile builder plus any the DEM source had, e.g. InSAR multilooking).
    /// The flyer smooths its frames by the same σ before slope, so both sides see the same
    /// terrain and their keypoints land alike. 0 = none; at most [`MAX_SMOOTHING_M`].
    pub smoothing_m: f32,
    /// The map's own horizontal error: 1σ, metres, along the tile's x (column) and y (row)
    /// axes, of where a frame registered on this tile lands relative to the true ground, for
    /// reasons the frame cannot see (the reference DEM's resolution and processing, e.g. an
    /// InSAR DEM's multilook blur that frames do not share). It moves a whole frame alike, so
    /// it never shows in a fix's residuals; every fix adds it to its covariance. 0 = none
    /// claimed; at most [`MAX_REFERENCE_SIGMA_M`].
    pub reference_sigma_m: [f32; 2],
    /// The map's own height noise: 1σ, metres, per tile pixel, of white noise with the map
    /// noise's power per unit area (a DEM filter that averaged neighbouring cells lowered their
    /// σ, not this power; e.g. an InSAR DEM's phase noise through its Cramér–Rao bound, undone
    /// for its filter). Frames registered on overlapping ground see the same noise, so a fix
    /// error it causes is shared by successive fixes, not new at each
    /// ([`Self::noise_power_m4`], `filter::map_noise_share`). 0 = none claimed (a map without
    /// noise of its own); at most [`MAX_HEIGHT_NOISE_M`].
    pub height_noise_m: f32,
}

/// Largest [`TileHeader::smoothing_m`] accepted, metres.
pub const MAX_SMOOTHING_M: f32 = 10_000.0;
/// Largest [`TileHeader::reference_sigma_m`] accepted, metres.
pub const MAX_REFERENCE_SIGMA_M: f32 = 10_000.0;
/// Largest [`TileHeader::height_noise_m`] accepted, metres.
pub const MAX_HEIGHT_NOISE_M: f32 = 10_000.0;

impl TileHeader<'_> {
    /// The SURF settings the tile was built with (frames should use the same).
    pub fn surf_config(&self) -> SurfConfig {
        SurfConfig {
            detector: DetectorConfig {
                octaves: self.octaves,
                layers: self.layers,
                threshold: self.threshold,
                min_scale_px: self.min_scale_px,
                max_lazy_responses: u32::MAX,
            },
            upright: self.upright,
        }
    }
    /// Geo coordinates (metres) of tile pixel coordinates `(x_px, y_px)`.
    pub fn pixel_to_geo(&self, x_px: f64, y_px: f64) -> (f64, f64) {
        (
            self.origin_x_m + x_px * self.pixel_x_m,
            self.origin_y_m + y_px * self.pixel_y_m,
        )
    }
    /// Mean ground sample distance, metres per pixel.
    pub fn pixel_m(&self) -> f64 {
        0.5 * (libm::fabs(self.pixel_x_m) + libm::fabs(self.pixel_y_m))
    }
    /// [`Self::reference_sigma_m`] as variances in tile pixels², `[x, y]`.
    pub fn reference_var_px2(&self) -> [f64; 2] {
        let v = |s: f32, px: f64| {
            let s = s as f64 / libm::fabs(px);
            s * s
        };
        [
            v(self.reference_sigma_m[0], self.pixel_x_m),
            v(self.reference_sigma_m[1], self.pixel_y_m),
        ]
    }
    /// The map's white height-noise power per unit area, m²·m² ([`Self::height_noise_m`]² ×
    /// pixel area): what a smoothing of any width leaves of the noise scales with it, so it
    /// compares directly with a frame's own (range noise² × frame pixel area).
    pub fn noise_power_m4(&self) -> f64 {
        let s = self.height_noise_m as f64;
        s * s * libm::fabs(self.pixel_x_m * self.pixel_y_m)
    }
    /// Whether the header's own fields are in range (shared by the parser and the writer).
    fn ranges_ok(&self) -> bool {
        let sigma_ok = |s: f32| (0.0..=MAX_REFERENCE_SIGMA_M).contains(&s);
        self.projection.len() <= MAX_PROJECTION_LEN
            && (0.0..=MAX_SMOOTHING_M).contains(&self.smoothing_m)
            && sigma_ok(self.reference_sigma_m[0])
            && sigma_ok(self.reference_sigma_m[1])
            && (0.0..=MAX_HEIGHT_NOISE_M).contains(&self.height_noise_m)
    }
}

/// Why a tile blob was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TileError {
    /// Shorter than the fixed parts, or its length disagrees with the counts.
    Truncated {
        /// Bytes the counts call for (or the minimum).
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// Magic bytes wrong: not a tile.
    BadMagic,
    /// A format version this code does not read.
    WrongVersion {
        /// Version found in the blob.
        found: u16,
    },
    /// CRC-32 mismatch: corrupted in storage or transit.
    BadChecksum {
        /// CRC stored in the blob.
        stored: u32,
        /// CRC computed over the blob.
        computed: u32,
    },
    /// Header does not decode, or is too long.
    BadHeader,
    /// Header values out of range (zero size, non-finite or zero pixel size, count mismatch,
    /// detector settings out of range, projection note too long).
    BadGeometry,
    /// A keypoint or descriptor holds a non-finite value or lies outside the tile.
    BadFeature {
        /// Index of the offending feature.
        index: u32,
    },
    /// The output buffer of the writer is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
}

impl fmt::Display for TileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Truncated { expected, got } => {
                write!(f, "tile truncated: {got} bytes, expected {expected}")
            }
            Self::BadMagic => write!(f, "not an Umbra tile (bad magic)"),
            Self::WrongVersion { found } => write!(
                f,
                "tile format version {found}, this build reads {TILE_FORMAT_VERSION}"
            ),
            Self::BadChecksum { stored, computed } => write!(
                f,
                "tile checksum mismatch: stored {stored:08x}, computed {computed:08x}"
            ),
            Self::BadHeader => write!(f, "tile header does not decode"),
            Self::BadGeometry => write!(f, "tile header values out of range"),
            Self::BadFeature { index } => write!(f, "tile feature {index} is invalid"),
            Self::BufferTooSmall { needed } => write!(f, "tile needs a {needed}-byte buffer"),
        }
    }
}

impl core::error::Error for TileError {}

fn rd_u16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}
fn rd_u32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}
fn rd_f32(b: &[u8], at: usize) -> f32 {
    b.get(at..at + 4)
        .and_then(|s| s.try_into().ok())
        .map_or(f32::NAN, f32::from_le_bytes)
}

const fn align4(n: usize) -> usize {
    (n + 3) & !3
}

/// Total blob length for a header of `header_len` bytes and `n` features, without a raster.
pub const fn tile_len(header_len: usize, n: usize) -> usize {
    tile_len_with_raster(header_len, n, 0)
}

/// Total blob length with a slope raster of `raster_px` pixels (0 = none).
pub const fn tile_len_with_raster(header_len: usize, n: usize, raster_px: usize) -> usize {
    align4(PREAMBLE_LEN + header_len)
        + n * (KEYPOINT_RECORD_LEN + DESCRIPTOR_RECORD_LEN)
        + align4(2 * raster_px)
        + 4
}

/// The reference slope raster stored in a tile, read in place: `width × height` raw
/// [`SlopePx`] values (degrees, 1/512° per unit, above 90° = no data), row-major, in tile pixel
/// axes. It is the very image the tile's features were detected on.
#[derive(Debug, Clone, Copy)]
pub struct SlopeRaster<'a> {
    bytes: &'a [u8],
    width: usize,
    height: usize,
}

impl SlopeRaster<'_> {
    /// Width in pixels (the tile's).
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels (the tile's).
    pub fn height(&self) -> usize {
        self.height
    }
    /// Raw bits of pixel `i` in row-major order; `u16::MAX` (no data) outside. One bounds
    /// check: the area search's inner loop reads tens of thousands of pixels per frame.
    #[inline]
    pub fn raw_index(&self, i: usize) -> u16 {
        match self.bytes.get(2 * i..2 * i + 2) {
            Some(&[a, b]) => u16::from_le_bytes([a, b]),
            _ => u16::MAX,
        }
    }
    /// Pixel at `(col, row)`; [`SLOPE_NODATA`] outside.
    #[inline]
    pub fn get(&self, col: usize, row: usize) -> SlopePx {
        // Both checked before the index arithmetic, which could otherwise wrap for a row far
        // outside.
        if col >= self.width || row >= self.height {
            return SLOPE_NODATA;
        }
        rd_u16(self.bytes, 2 * (row * self.width + col)).map_or(SLOPE_NODATA, SlopePx::from_bits)
    }
}

/// A validated tile, borrowing its bytes (e.g. straight from flash).
#[derive(Debug, Clone, Copy)]
pub struct Tile<'a> {
    header: TileHeader<'a>,
    keypoints: &'a [u8],
    descriptors: &'a [u8],
    count: usize,
    raster: Option<SlopeRaster<'a>>,
}

impl<'a> Tile<'a> {
    /// Validate everything once: magic, version, lengths, checksum, header ranges, and every
    /// keypoint and descriptor value. Afterwards accessors cannot fail.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, TileError> {
        Self::parse_inner(bytes, true)
    }

    /// [`Self::parse`] without the CRC and the per-feature checks, for bytes that passed
    /// [`Self::parse`] before and cannot have changed since (a private buffer of
    /// [`crate::atlas::BufferedAtlas`]): the layout is still checked, so a wrong call gives an
    /// error or a tile, never a panic.
    pub(crate) fn parse_validated(bytes: &'a [u8]) -> Result<Self, TileError> {
        Self::parse_inner(bytes, false)
    }

    fn parse_inner(bytes: &'a [u8], full: bool) -> Result<Self, TileError> {
        let min = PREAMBLE_LEN + 4;
        if bytes.len() < min {
            return Err(TileError::Truncated {
                expected: min,
                got: bytes.len(),
            });
        }
        if bytes.get(..8) != Some(&TILE_MAGIC[..]) {
            return Err(TileError::BadMagic);
        }
        let bad_len = TileError::Truncated {
            expected: min,
            got: bytes.len(),
        };
        let version = rd_u16(bytes, 8).ok_or(bad_len)?;
        if version != TILE_FORMAT_VERSION {
            return Err(TileError::WrongVersion { found: version });
        }
        let header_len = rd_u16(bytes, 10).ok_or(bad_len)? as usize;
        let count = rd_u32(bytes, 12).ok_or(bad_len)? as usize;
        let raster_px = rd_u32(bytes, 16).ok_or(bad_len)? as usize;
        if header_len > MAX_HEADER_LEN || count > MAX_TILE_FEATURES || raster_px > MAX_RASTER_PX {
            return Err(TileError::BadHeader);
        }
        let expected = tile_len_with_raster(header_len, count, raster_px);
        if bytes.len() != expected {
            return Err(TileError::Truncated {
                expected,
                got: bytes.len(),
            });
        }
        let body = bytes.get(..expected - 4).ok_or(bad_len)?;
        let stored = rd_u32(bytes, expected - 4).ok_or(bad_len)?;
        let computed = if full { CRC.checksum(body) } else { stored };
        if stored != computed {
            return Err(TileError::BadChecksum { stored, computed });
        }
        let hbytes = bytes
            .get(PREAMBLE_LEN..PREAMBLE_LEN + header_len)
            .ok_or(TileError::BadHeader)?;
        let (header, rest): (TileHeader<'a>, &[u8]) =
            postcard::take_from_bytes(hbytes).map_err(|_| TileError::BadHeader)?;
        if !rest.is_empty() {
            return Err(TileError::BadHeader);
        }
        let finite_nz = |v: f64| v.is_finite() && v != 0.0;
        let detector_ok = header.surf_config().detector.validate().is_ok();
        if header.width_px == 0
            || header.height_px == 0
            || header.feature_count as usize != count
            || !finite_nz(header.pixel_x_m)
            || !finite_nz(header.pixel_y_m)
            || !header.origin_x_m.is_finite()
            || !header.origin_y_m.is_finite()
            || !header.ranges_ok()
            || !detector_ok
            || (raster_px != 0
                && Some(raster_px)
                    != (header.width_px as usize).checked_mul(header.height_px as usize))
        {
            return Err(TileError::BadGeometry);
        }
        let kp_start = align4(PREAMBLE_LEN + header_len);
        let d_start = kp_start + count * KEYPOINT_RECORD_LEN;
        let keypoints = bytes.get(kp_start..d_start).ok_or(bad_len)?;
        let descriptors = bytes
            .get(d_start..d_start + count * DESCRIPTOR_RECORD_LEN)
            .ok_or(bad_len)?;
        let r_start = d_start + count * DESCRIPTOR_RECORD_LEN;
        // Any u16 is a valid raster value (above 90° reads as no data), so nothing to check.
        let raster = if raster_px == 0 {
            None
        } else {
            Some(SlopeRaster {
                bytes: bytes.get(r_start..r_start + 2 * raster_px).ok_or(bad_len)?,
                width: header.width_px as usize,
                height: header.height_px as usize,
            })
        };
        let tile = Self {
            header,
            keypoints,
            descriptors,
            count,
            raster,
        };
        let (w, h) = (header.width_px as f32, header.height_px as f32);
        // Without `full` the features passed this loop when the bytes were first parsed.
        for i in 0..if full { count } else { 0 } {
            let k = tile.keypoint(i);
            let inside = k.x_px >= -0.5 && k.y_px >= -0.5 && k.x_px <= w - 0.5 && k.y_px <= h - 0.5;
            let finite = k.response.is_finite()
                && k.orientation_rad.is_finite()
                && k.scale_px.is_finite()
                && k.scale_px > 0.0;
            let desc_ok = (0..DESCRIPTOR_LEN).all(|j| tile.descriptor_value(i, j).is_finite());
            if !(inside && finite && desc_ok) {
                return Err(TileError::BadFeature { index: i as u32 });
            }
        }
        Ok(tile)
    }

    /// The header.
    pub fn header(&self) -> &TileHeader<'a> {
        &self.header
    }
    /// The reference slope raster, if the tile carries one.
    pub fn slope_raster(&self) -> Option<&SlopeRaster<'a>> {
        self.raster.as_ref()
    }
    /// Number of features.
    pub fn len(&self) -> usize {
        self.count
    }
    /// No features.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Keypoint `i` (tile pixel coordinates); a zeroed keypoint for an index out of range.
    pub fn keypoint(&self, i: usize) -> Keypoint {
        let at = i * KEYPOINT_RECORD_LEN;
        let b = self.keypoints;
        Keypoint {
            x_px: rd_f32(b, at),
            y_px: rd_f32(b, at + 4),
            scale_px: rd_f32(b, at + 8),
            orientation_rad: rd_f32(b, at + 12),
            response: rd_f32(b, at + 16),
            laplacian_positive: rd_u32(b, at + 20).unwrap_or(0) & FLAG_LAPLACIAN_POSITIVE != 0,
        }
    }

    /// Position `(x_px, y_px)` of keypoint `i` in tile pixels (NaN out of range). Cheaper than
    /// [`Self::keypoint`] for position gates.
    #[inline]
    pub fn position_px(&self, i: usize) -> (f32, f32) {
        let at = i * KEYPOINT_RECORD_LEN;
        (rd_f32(self.keypoints, at), rd_f32(self.keypoints, at + 4))
    }

    /// Laplacian sign of keypoint `i` (the flags word only; `false` out of range). Cheaper than
    /// [`Self::keypoint`] for the matcher's sign gate.
    #[inline]
    pub fn laplacian_positive(&self, i: usize) -> bool {
        rd_u32(self.keypoints, i * KEYPOINT_RECORD_LEN + 20).unwrap_or(0) & FLAG_LAPLACIAN_POSITIVE
            != 0
    }

    /// Component `j` of descriptor `i` (NaN out of range, which `parse` rules out for valid
    /// indices).
    #[inline]
    pub fn descriptor_value(&self, i: usize, j: usize) -> f32 {
        rd_f32(self.descriptors, (i * DESCRIPTOR_LEN + j) * 4)
    }

    /// The raw little-endian bytes of descriptor `i` (empty out of range).
    #[inline]
    pub fn descriptor_bytes(&self, i: usize) -> &'a [u8] {
        let at = i * DESCRIPTOR_RECORD_LEN;
        self.descriptors
            .get(at..at + DESCRIPTOR_RECORD_LEN)
            .unwrap_or(&[])
    }

    /// Descriptor `i` decoded into an array.
    pub fn descriptor(&self, i: usize) -> Descriptor {
        let mut d = [0.0f32; DESCRIPTOR_LEN];
        for (j, v) in d.iter_mut().enumerate() {
            *v = self.descriptor_value(i, j);
        }
        d
    }
}

/// The CRC-32 a tile blob carries in its last four bytes (little-endian), as written: a digest
/// of the whole tile. `None` for a blob shorter than four bytes (not checked against the
/// contents: [`Tile::parse`] does that).
pub fn stored_crc(bytes: &[u8]) -> Option<u32> {
    let at = bytes.len().checked_sub(4)?;
    bytes
        .get(at..)
        .and_then(|b| b.try_into().ok())
        .map(u32::from_le_bytes)
}

/// Serialise a tile without a slope raster into `out`; returns the number of bytes written.
/// No allocation: the ground side passes a `Vec` sized with [`tile_len`] (header length is
/// known after encoding; passing `tile_len(MAX_HEADER_LEN, n)` bytes is always enough).
pub fn write_tile(
    header: &TileHeader<'_>,
    features: &[Feature],
    out: &mut [u8],
) -> Result<usize, TileError> {
    write_tile_with_raster(header, features, None, out)
}

/// [`write_tile`] with the reference slope raster (`width_px × height_px` pixels, row-major)
/// the features were detected on; `out` needs
/// `tile_len_with_raster(MAX_HEADER_LEN, n, width × height)` bytes.
pub fn write_tile_with_raster(
    header: &TileHeader<'_>,
    features: &[Feature],
    raster: Option<&[SlopePx]>,
    out: &mut [u8],
) -> Result<usize, TileError> {
    if features.len() > MAX_TILE_FEATURES || header.feature_count as usize != features.len() {
        return Err(TileError::BadGeometry);
    }
    let raster_px = raster.map_or(0, <[SlopePx]>::len);
    if let Some(r) = raster
        && (r.is_empty()
            || r.len() > MAX_RASTER_PX
            || Some(r.len()) != (header.width_px as usize).checked_mul(header.height_px as usize))
    {
        return Err(TileError::BadGeometry);
    }
    if !header.ranges_ok() {
        return Err(TileError::BadGeometry);
    }
    let n = features.len();
    let too_small = TileError::BufferTooSmall {
        needed: tile_len_with_raster(MAX_HEADER_LEN, n, raster_px),
    };
    let hdr_area = out
        .get_mut(PREAMBLE_LEN..PREAMBLE_LEN + MAX_HEADER_LEN)
        .ok_or(too_small)?;
    let header_len = postcard::to_slice(header, hdr_area)
        .map_err(|_| TileError::BadHeader)?
        .len();
    let total = tile_len_with_raster(header_len, n, raster_px);
    let out = out.get_mut(..total).ok_or(too_small)?;
    fn put(out: &mut [u8], at: usize, bytes: &[u8]) {
        if let Some(dst) = out.get_mut(at..at + bytes.len()) {
            dst.copy_from_slice(bytes);
        }
    }
    put(out, 0, &TILE_MAGIC);
    put(out, 8, &TILE_FORMAT_VERSION.to_le_bytes());
    put(out, 10, &(header_len as u16).to_le_bytes());
    put(out, 12, &(n as u32).to_le_bytes());
    put(out, 16, &(raster_px as u32).to_le_bytes());
    let kp_start = align4(PREAMBLE_LEN + header_len);
    let pad = kp_start - PREAMBLE_LEN - header_len;
    put(
        out,
        PREAMBLE_LEN + header_len,
        [0u8; 3].get(..pad).unwrap_or(&[]),
    );
    let d_start = kp_start + n * KEYPOINT_RECORD_LEN;
    for (i, f) in features.iter().enumerate() {
        let k = &f.keypoint;
        let at = kp_start + i * KEYPOINT_RECORD_LEN;
        put(out, at, &k.x_px.to_le_bytes());
        put(out, at + 4, &k.y_px.to_le_bytes());
        put(out, at + 8, &k.scale_px.to_le_bytes());
        put(out, at + 12, &k.orientation_rad.to_le_bytes());
        put(out, at + 16, &k.response.to_le_bytes());
        let flags = if k.laplacian_positive {
            FLAG_LAPLACIAN_POSITIVE
        } else {
            0
        };
        put(out, at + 20, &flags.to_le_bytes());
        for (j, v) in f.descriptor.iter().enumerate() {
            put(
                out,
                d_start + (i * DESCRIPTOR_LEN + j) * 4,
                &v.to_le_bytes(),
            );
        }
    }
    let r_start = d_start + n * DESCRIPTOR_RECORD_LEN;
    for (i, p) in raster.unwrap_or(&[]).iter().enumerate() {
        put(out, r_start + 2 * i, &p.to_bits().to_le_bytes());
    }
    // Padding after an odd raster, so the CRC covers defined bytes.
    if raster_px % 2 == 1 {
        put(out, r_start + 2 * raster_px, &[0, 0]);
    }
    let crc = CRC.checksum(out.get(..total - 4).unwrap_or(&[]));
    put(out, total - 4, &crc.to_le_bytes());
    Ok(total)
}
