//! Flight atlas: the reference of a whole hop corridor as a set of bounded tiles on one pixel
//! grid, with a checksummed index, read without allocating.
//!
//! A 16 km map at 20 m carries a 1.28 MB slope raster and a 32 km one 5 MB: more than a flight
//! computer's internal flash, and more than one frame ever needs. The ground cuts the map into
//! overlapping tiles (each an ordinary [`Tile`]); the flyer keeps the small index at hand and
//! only the tile under its prior in reach. The prose spec with byte tables is
//! `docs/tile-format.md` ("Atlas").
//!
//! * [`Atlas::parse`] validates the index (magic, version, lengths, CRC, every entry).
//! * [`select`](Atlas::select) ranks the tiles for a frame under a prior: the tile that holds
//!   the frame's reach deepest first; when no tile holds all of it (the frame straddles a tile
//!   edge), the neighbours that reach into it follow, at most [`MAX_ATLAS_CANDIDATES`].
//! * A [`TileSource`] gives a tile's bytes: [`MappedAtlas`] when the whole atlas is addressable
//!   (internal or memory-mapped flash; every tile validated once, up front), [`BufferedAtlas`]
//!   when tiles live in external storage and one at a time is copied into a RAM buffer of
//!   caller-chosen size.
//! * [`AtlasNavigator::locate_dem`] runs the [`Navigator`] on the selected tile and, when it
//!   gives no fix and the frame straddles, on the next candidates (the frame's slope and features
//!   are extracted once: every tile of an atlas shares the extraction settings).
//!
//! Coordinates: *atlas pixels* are the grid's pixel axes (x = column, y = row, pixel centres at
//! integers); tile `i`'s pixel `(0, 0)` is atlas pixel `(col0, row0)` of its entry, so a tile
//! pixel coordinate plus the entry's offset is an atlas pixel coordinate, exactly.

use crate::frame::DemPatch;
use crate::navigator::{FrameReport, NavConfig, NavError, NavWorkspace, Navigator, Prior};
use crate::tile::{MAX_PROJECTION_LEN, Tile, TileError, TileHeader};
use core::fmt;
use serde::{Deserialize, Serialize};

/// Magic bytes at offset 0 of an atlas.
pub const ATLAS_MAGIC: [u8; 8] = *b"UMBRAATL";
/// Atlas format version this code reads and writes.
pub const ATLAS_FORMAT_VERSION: u16 = 1;
/// Bytes before the atlas header: magic, version, header length, tile count.
pub const ATLAS_PREAMBLE_LEN: usize = 16;
/// Largest atlas header accepted, bytes.
pub const MAX_ATLAS_HEADER_LEN: usize = 512;
/// Bytes per index entry: `col0`, `row0` (`i32`), `width`, `height`, `offset`, `length`,
/// `tile CRC` (`u32`).
pub const ATLAS_ENTRY_LEN: usize = 28;
/// Most tiles an atlas may index (4096 tiles of 4 km cover a 256 km square).
pub const MAX_ATLAS_TILES: usize = 4096;
/// Most tiles one frame is tried on: the tile that holds it deepest and, at a tile corner,
/// its three neighbours.
pub const MAX_ATLAS_CANDIDATES: usize = 4;
/// Largest tile side, pixels (a tile is one [`Tile`]; its raster alone is 2 B per pixel).
pub const MAX_ATLAS_TILE_SIDE: u32 = 4096;

const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The atlas grid and what every tile shares.
///
/// Geo coordinates of atlas pixel `(x, y)`: `X = origin_x_m + x·pixel_x_m`,
/// `Y = origin_y_m + y·pixel_y_m` (metres of `projection`; `pixel_y_m` negative for north-up).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AtlasHeader<'a> {
    /// Grid width, pixels (every tile lies inside `0..width_px`).
    pub width_px: u32,
    /// Grid height, pixels.
    pub height_px: u32,
    /// Geo x of the centre of atlas pixel (0, 0), m.
    pub origin_x_m: f64,
    /// Geo y of the centre of atlas pixel (0, 0), m.
    pub origin_y_m: f64,
    /// Geo x step per column, m.
    pub pixel_x_m: f64,
    /// Geo y step per row, m (negative for north-up).
    pub pixel_y_m: f64,
    /// Projection note, as in every tile.
    #[serde(borrow)]
    pub projection: &'a str,
    /// Overlap the ground built in: each tile reaches at least this many pixels beyond the
    /// part of the grid it is the deepest tile for (its core), where the grid allows. A frame
    /// whose reach (half-diagonal plus 3σ) is within it never needs a second tile.
    pub margin_px: u32,
    /// Every tile's [`TileHeader::smoothing_m`], m.
    pub smoothing_m: f32,
    /// Every tile's SURF octaves.
    pub octaves: u8,
    /// Every tile's SURF layers per octave.
    pub layers: u8,
    /// Every tile's detector threshold, deg².
    pub threshold: f32,
    /// Every tile's smallest keypoint scale, px.
    pub min_scale_px: f32,
    /// Every tile's U-SURF flag.
    pub upright: bool,
}

impl AtlasHeader<'_> {
    /// Mean ground sample distance, metres per pixel.
    pub fn pixel_m(&self) -> f64 {
        0.5 * (libm::fabs(self.pixel_x_m) + libm::fabs(self.pixel_y_m))
    }
    /// Atlas pixel coordinates of geo coordinates (metres).
    pub fn geo_to_pixel(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        (
            (x_m - self.origin_x_m) / self.pixel_x_m,
            (y_m - self.origin_y_m) / self.pixel_y_m,
        )
    }
    /// Geo coordinates (metres) of atlas pixel coordinates.
    pub fn pixel_to_geo(&self, x_px: f64, y_px: f64) -> (f64, f64) {
        (
            self.origin_x_m + x_px * self.pixel_x_m,
            self.origin_y_m + y_px * self.pixel_y_m,
        )
    }
    /// The SURF settings every tile was built with.
    pub fn surf_config(&self) -> crate::surf::SurfConfig {
        crate::surf::SurfConfig {
            detector: crate::detector::DetectorConfig {
                octaves: self.octaves,
                layers: self.layers,
                threshold: self.threshold,
                min_scale_px: self.min_scale_px,
                max_lazy_responses: u32::MAX,
            },
            upright: self.upright,
        }
    }
    fn valid(&self) -> bool {
        let finite_nz = |v: f64| v.is_finite() && v != 0.0;
        self.width_px > 0
            && self.height_px > 0
            && finite_nz(self.pixel_x_m)
            && finite_nz(self.pixel_y_m)
            && self.origin_x_m.is_finite()
            && self.origin_y_m.is_finite()
            && self.projection.len() <= MAX_PROJECTION_LEN
            && (0.0..=crate::tile::MAX_SMOOTHING_M).contains(&self.smoothing_m)
            && self.surf_config().detector.validate().is_ok()
    }
    /// Whether `t`, placed at `e`, sits on this grid with this atlas's extraction settings
    /// (bit-for-bit equal floats: the ground writes them from one value).
    fn holds(&self, e: &AtlasEntry, t: &TileHeader<'_>) -> bool {
        let (gx, gy) = self.pixel_to_geo(e.col0 as f64, e.row0 as f64);
        t.width_px == e.width
            && t.height_px == e.height
            && t.pixel_x_m.to_bits() == self.pixel_x_m.to_bits()
            && t.pixel_y_m.to_bits() == self.pixel_y_m.to_bits()
            && libm::fabs(t.origin_x_m - gx) <= 1e-6 * libm::fabs(self.pixel_x_m)
            && libm::fabs(t.origin_y_m - gy) <= 1e-6 * libm::fabs(self.pixel_y_m)
            && t.smoothing_m.to_bits() == self.smoothing_m.to_bits()
            && t.octaves == self.octaves
            && t.layers == self.layers
            && t.threshold.to_bits() == self.threshold.to_bits()
            && t.min_scale_px.to_bits() == self.min_scale_px.to_bits()
            && t.upright == self.upright
    }
}

/// One tile in the index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AtlasEntry {
    /// Atlas column of the tile's pixel (0, 0).
    pub col0: i32,
    /// Atlas row of the tile's pixel (0, 0).
    pub row0: i32,
    /// Tile width, px.
    pub width: u32,
    /// Tile height, px.
    pub height: u32,
    /// Byte offset of the tile blob from the start of the atlas (a multiple of 4).
    pub offset: u32,
    /// Tile blob length, bytes.
    pub length: u32,
    /// The CRC-32 the tile blob carries in its last 4 bytes.
    pub crc: u32,
}

impl AtlasEntry {
    /// Signed depth of atlas point `(x, y)` inside this tile, px: the distance to the nearest
    /// tile edge (pixel borders at ±0.5), negative outside.
    pub fn depth_px(&self, x: f64, y: f64) -> f64 {
        let (x0, y0) = (self.col0 as f64 - 0.5, self.row0 as f64 - 0.5);
        let (x1, y1) = (x0 + self.width as f64, y0 + self.height as f64);
        let dx = libm::fmin(x - x0, x1 - x);
        let dy = libm::fmin(y - y0, y1 - y);
        libm::fmin(dx, dy)
    }
    /// [`Self::depth_px`] counting only the tile's edges inside a `grid_w × grid_h` grid: an
    /// edge on the grid's own border has no neighbour beyond it, so a frame near it is no
    /// reason to try another tile. Infinite for a tile that spans the whole grid.
    pub fn inner_depth_px(&self, x: f64, y: f64, grid_w: u32, grid_h: u32) -> f64 {
        let (x0, y0) = (self.col0 as f64 - 0.5, self.row0 as f64 - 0.5);
        let (x1, y1) = (x0 + self.width as f64, y0 + self.height as f64);
        let end_c = self.col0 as i64 + self.width as i64;
        let end_r = self.row0 as i64 + self.height as i64;
        let mut d = f64::INFINITY;
        if self.col0 > 0 {
            d = libm::fmin(d, x - x0);
        }
        if end_c < grid_w as i64 {
            d = libm::fmin(d, x1 - x);
        }
        if self.row0 > 0 {
            d = libm::fmin(d, y - y0);
        }
        if end_r < grid_h as i64 {
            d = libm::fmin(d, y1 - y);
        }
        d
    }
    /// The prior moved from atlas pixels into this tile's pixels.
    pub fn tile_prior(&self, p: &Prior) -> Prior {
        Prior {
            center_tile_px: [
                p.center_tile_px[0] - self.col0 as f32,
                p.center_tile_px[1] - self.row0 as f32,
            ],
            ..*p
        }
    }
}

/// Why an atlas, or a tile it names, was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AtlasError {
    /// Shorter than its preamble or index.
    Truncated {
        /// Bytes the index needs (or the minimum).
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// The first 8 bytes are not `UMBRAATL`.
    BadMagic,
    /// A version other than [`ATLAS_FORMAT_VERSION`].
    WrongVersion {
        /// Version found.
        found: u16,
    },
    /// The index CRC does not match.
    BadChecksum {
        /// CRC stored.
        stored: u32,
        /// CRC computed.
        computed: u32,
    },
    /// Header too long, does not decode, or leaves trailing bytes; or too many tiles.
    BadHeader,
    /// Header values out of range (zero size, non-finite pixel, detector settings).
    BadGeometry,
    /// An entry out of range: empty or larger than [`MAX_ATLAS_TILE_SIDE`], outside the grid,
    /// blob inside the index or not 4-byte aligned.
    BadEntry {
        /// Entry index.
        index: u16,
    },
    /// A tile that does not parse.
    Tile {
        /// Entry index.
        index: u16,
        /// The tile's error.
        error: TileError,
    },
    /// A tile that parses but is not the one the index names: other CRC, size, place on the
    /// grid or extraction settings.
    TileMismatch {
        /// Entry index.
        index: u16,
    },
    /// Index beyond the tile count.
    NoSuchTile {
        /// Index asked for.
        index: u16,
    },
    /// The tile is larger than the source's buffer (or its capacity of tiles).
    TooLarge {
        /// Entry index (or tile count).
        index: u16,
        /// Bytes (or tiles) needed.
        needed: u32,
    },
    /// The storage reader failed.
    Read {
        /// Entry index.
        index: u16,
    },
    /// Output buffer too small for [`write_atlas_index`].
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
}

impl fmt::Display for AtlasError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Truncated { expected, got } => {
                write!(
                    f,
                    "atlas truncated: {got} bytes, the index needs {expected}"
                )
            }
            Self::BadMagic => write!(f, "not an Umbra atlas (bad magic)"),
            Self::WrongVersion { found } => write!(
                f,
                "atlas format version {found}, this reader reads {ATLAS_FORMAT_VERSION}"
            ),
            Self::BadChecksum { stored, computed } => write!(
                f,
                "atlas index checksum mismatch: stored {stored:#010x}, computed {computed:#010x}"
            ),
            Self::BadHeader => write!(f, "atlas header malformed"),
            Self::BadGeometry => write!(f, "atlas header values out of range"),
            Self::BadEntry { index } => write!(f, "atlas entry {index} out of range"),
            Self::Tile { index, error } => write!(f, "atlas tile {index}: {error}"),
            Self::TileMismatch { index } => write!(
                f,
                "atlas tile {index} is not the tile its entry names (CRC, size, grid or settings)"
            ),
            Self::NoSuchTile { index } => write!(f, "no atlas tile {index}"),
            Self::TooLarge { index, needed } => {
                write!(
                    f,
                    "atlas tile {index} needs {needed} bytes (or tiles), more than the source holds"
                )
            }
            Self::Read { index } => write!(f, "reading atlas tile {index} failed"),
            Self::BufferTooSmall { needed } => {
                write!(f, "output buffer too small: {needed} bytes needed")
            }
        }
    }
}
impl core::error::Error for AtlasError {}

/// Bytes of an index with header length `header_len` and `n` tiles: preamble, header padded to
/// 4, entries, CRC. Tile blobs may follow from this offset on.
/// Saturates at `usize::MAX` for sizes no atlas can have.
pub const fn atlas_index_len(header_len: usize, n: usize) -> usize {
    align4(ATLAS_PREAMBLE_LEN.saturating_add(header_len))
        .saturating_add(n.saturating_mul(ATLAS_ENTRY_LEN))
        .saturating_add(4)
}

const fn align4(n: usize) -> usize {
    n.saturating_add(3) & !3
}

fn rd_u16(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}
fn rd_u32(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// A validated atlas index, borrowing its bytes.
#[derive(Debug, Clone, Copy)]
pub struct Atlas<'a> {
    header: AtlasHeader<'a>,
    entries: &'a [u8],
    count: usize,
    index_len: usize,
    crc: u32,
}

/// Tiles ranked for one frame by [`Atlas::select`], deepest first.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Candidates {
    /// Tile indexes, deepest first; the first `count` are valid.
    pub tiles: [u16; MAX_ATLAS_CANDIDATES],
    /// Their depths ([`AtlasEntry::inner_depth_px`] of the prior's centre), atlas px.
    pub depth_px: [f32; MAX_ATLAS_CANDIDATES],
    /// Valid entries.
    pub count: u8,
    /// The frame's reach: half its diagonal plus 3σ of the prior, atlas px.
    pub reach_px: f32,
    /// Half the frame's diagonal, atlas px: a frame at the prior centre lies wholly inside a
    /// tile in which that centre is at least this deep.
    pub half_diag_px: f32,
    /// No tile holds the whole reach: the frame may straddle a tile edge.
    pub straddles: bool,
}

impl Candidates {
    /// The ranked tile indexes.
    pub fn as_slice(&self) -> &[u16] {
        self.tiles.get(..self.count as usize).unwrap_or(&[])
    }
}

impl<'a> Atlas<'a> {
    /// Validate the index at the start of `bytes` (the tiles may follow it in the same slice,
    /// or not be there at all): magic, version, lengths, CRC, header ranges, every entry.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, AtlasError> {
        let min = ATLAS_PREAMBLE_LEN + 4;
        let short = AtlasError::Truncated {
            expected: min,
            got: bytes.len(),
        };
        if bytes.len() < min {
            return Err(short);
        }
        if bytes.get(..8) != Some(&ATLAS_MAGIC[..]) {
            return Err(AtlasError::BadMagic);
        }
        let version = rd_u16(bytes, 8).ok_or(short)?;
        if version != ATLAS_FORMAT_VERSION {
            return Err(AtlasError::WrongVersion { found: version });
        }
        let header_len = rd_u16(bytes, 10).ok_or(short)? as usize;
        let count = rd_u32(bytes, 12).ok_or(short)? as usize;
        if header_len > MAX_ATLAS_HEADER_LEN || count == 0 || count > MAX_ATLAS_TILES {
            return Err(AtlasError::BadHeader);
        }
        let index_len = atlas_index_len(header_len, count);
        if bytes.len() < index_len {
            return Err(AtlasError::Truncated {
                expected: index_len,
                got: bytes.len(),
            });
        }
        let stored = rd_u32(bytes, index_len - 4).ok_or(short)?;
        let computed = CRC.checksum(bytes.get(..index_len - 4).ok_or(short)?);
        if stored != computed {
            return Err(AtlasError::BadChecksum { stored, computed });
        }
        let hbytes = bytes
            .get(ATLAS_PREAMBLE_LEN..ATLAS_PREAMBLE_LEN + header_len)
            .ok_or(AtlasError::BadHeader)?;
        let (header, rest): (AtlasHeader<'a>, &[u8]) =
            postcard::take_from_bytes(hbytes).map_err(|_| AtlasError::BadHeader)?;
        if !rest.is_empty() {
            return Err(AtlasError::BadHeader);
        }
        if !header.valid() {
            return Err(AtlasError::BadGeometry);
        }
        let e_start = align4(ATLAS_PREAMBLE_LEN + header_len);
        let entries = bytes
            .get(e_start..e_start + count * ATLAS_ENTRY_LEN)
            .ok_or(short)?;
        let atlas = Self {
            header,
            entries,
            count,
            index_len,
            crc: stored,
        };
        for i in 0..count {
            let e = atlas
                .entry(i)
                .ok_or(AtlasError::BadEntry { index: i as u16 })?;
            let inside = e.col0 >= 0
                && e.row0 >= 0
                && (e.col0 as u64 + e.width as u64) <= header.width_px as u64
                && (e.row0 as u64 + e.height as u64) <= header.height_px as u64;
            let sized = (1..=MAX_ATLAS_TILE_SIDE).contains(&e.width)
                && (1..=MAX_ATLAS_TILE_SIDE).contains(&e.height);
            let placed = e.offset as usize >= index_len
                && e.offset % 4 == 0
                && e.length >= 24
                && (e.offset as u64 + e.length as u64) <= u32::MAX as u64;
            if !(inside && sized && placed) {
                return Err(AtlasError::BadEntry { index: i as u16 });
            }
        }
        Ok(atlas)
    }

    /// The header.
    pub fn header(&self) -> &AtlasHeader<'a> {
        &self.header
    }
    /// Number of tiles.
    pub fn len(&self) -> usize {
        self.count
    }
    /// Never true for a parsed atlas (it holds at least one tile).
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// The index's CRC-32 (its last four bytes): a digest of the whole index, and through the
    /// entries' tile CRCs of every tile.
    pub fn index_crc(&self) -> u32 {
        self.crc
    }
    /// Bytes of the index (the tiles' offsets start at or after it).
    pub fn index_len(&self) -> usize {
        self.index_len
    }

    /// Entry `i`, `None` beyond the count.
    pub fn entry(&self, i: usize) -> Option<AtlasEntry> {
        let at = i.checked_mul(ATLAS_ENTRY_LEN)?;
        let b = self.entries.get(at..at.checked_add(ATLAS_ENTRY_LEN)?)?;
        Some(AtlasEntry {
            col0: rd_u32(b, 0)? as i32,
            row0: rd_u32(b, 4)? as i32,
            width: rd_u32(b, 8)?,
            height: rd_u32(b, 12)?,
            offset: rd_u32(b, 16)?,
            length: rd_u32(b, 20)?,
            crc: rd_u32(b, 24)?,
        })
    }

    /// Rank the tiles for a `frame_w × frame_h` frame under `prior` (atlas pixels; `scale` is
    /// atlas px per frame px). The frame's reach is half its diagonal at the largest scale
    /// within 3σ plus 3σ of position; a tile is a candidate when the prior's centre is less than
    /// the reach outside it (a square test). Candidates rank by [`AtlasEntry::inner_depth_px`]
    /// (edges on the grid's border do not count: nothing lies beyond them), deepest first,
    /// exact ties to the lower index. When the deepest tile holds the whole reach it is the
    /// only candidate; otherwise the frame straddles and up to [`MAX_ATLAS_CANDIDATES`] follow.
    /// Empty when no tile is in reach or the prior is not finite. One pass over the index.
    pub fn select(&self, prior: &Prior, frame_w: usize, frame_h: usize) -> Candidates {
        let (cx, cy) = (
            prior.center_tile_px[0] as f64,
            prior.center_tile_px[1] as f64,
        );
        // The navigator's own footprint: the largest scale within 3σ, |σ| of position.
        let scale = prior.scale as f64 + 3.0 * libm::fabs(prior.scale_sigma as f64);
        let half_diag = 0.5 * libm::hypot(frame_w as f64, frame_h as f64) * scale;
        let reach = half_diag + 3.0 * libm::fabs(prior.sigma_px as f64);
        let mut out = Candidates {
            tiles: [0; MAX_ATLAS_CANDIDATES],
            depth_px: [f32::NEG_INFINITY; MAX_ATLAS_CANDIDATES],
            count: 0,
            reach_px: reach as f32,
            half_diag_px: half_diag as f32,
            straddles: false,
        };
        if !(cx.is_finite() && cy.is_finite() && reach.is_finite()) {
            return out;
        }
        let (gw, gh) = (self.header.width_px, self.header.height_px);
        // Ranked in f64 (ties keep index order exactly); reported as f32.
        let mut depth = [f64::NEG_INFINITY; MAX_ATLAS_CANDIDATES];
        let mut n = 0usize;
        for i in 0..self.count {
            let Some(e) = self.entry(i) else { break };
            if e.depth_px(cx, cy) <= -reach {
                continue;
            }
            let d = e.inner_depth_px(cx, cy, gw, gh);
            let mut at = n;
            while at > 0 && depth.get(at - 1).is_some_and(|&p| p < d) {
                at -= 1;
            }
            if at >= MAX_ATLAS_CANDIDATES {
                continue;
            }
            let mut j = n.min(MAX_ATLAS_CANDIDATES - 1);
            while j > at {
                if let (Some(&t), Some(&dp)) = (out.tiles.get(j - 1), depth.get(j - 1)) {
                    if let Some(s) = out.tiles.get_mut(j) {
                        *s = t;
                    }
                    if let Some(s) = depth.get_mut(j) {
                        *s = dp;
                    }
                }
                j -= 1;
            }
            if let Some(s) = out.tiles.get_mut(at) {
                *s = i as u16;
            }
            if let Some(s) = depth.get_mut(at) {
                *s = d;
            }
            n = (n + 1).min(MAX_ATLAS_CANDIDATES);
        }
        if n > 0 && depth[0] >= reach {
            n = 1;
        } else if n > 0 {
            out.straddles = true;
        }
        out.count = n as u8;
        for (o, &d) in out.depth_px.iter_mut().zip(&depth).take(n) {
            *o = d as f32;
        }
        out
    }
}

/// Where a navigator gets tile `i`'s bytes.
pub trait TileSource {
    /// The atlas index.
    fn atlas(&self) -> &Atlas<'_>;
    /// Tile `index`, validated and checked against its entry.
    fn tile(&mut self, index: u16) -> Result<Tile<'_>, AtlasError>;
}

/// Parse tile `index` from `bytes` and check it against its entry.
fn check_tile<'b>(
    atlas: &Atlas<'_>,
    index: u16,
    e: &AtlasEntry,
    bytes: &'b [u8],
) -> Result<Tile<'b>, AtlasError> {
    let tile = Tile::parse(bytes).map_err(|error| AtlasError::Tile { index, error })?;
    if crate::tile::stored_crc(bytes) != Some(e.crc) || !atlas.header.holds(e, tile.header()) {
        return Err(AtlasError::TileMismatch { index });
    }
    Ok(tile)
}

/// A whole atlas in addressable memory (internal flash, memory-mapped external flash, or a
/// host buffer), with up to `N` tiles each validated once at [`MappedAtlas::new`] (CRC and
/// every feature) and kept parsed, so a frame never pays for a checksum. RAM: `N` parsed tile
/// handles (`size_of::<Option<Tile>>()` each, ≈ 0.2 KB), no tile bytes.
#[derive(Debug, Clone)]
pub struct MappedAtlas<'a, const N: usize> {
    atlas: Atlas<'a>,
    tiles: [Option<Tile<'a>>; N],
}

impl<'a, const N: usize> MappedAtlas<'a, N> {
    /// Parse the index at the start of `bytes` and every tile it names.
    pub fn new(bytes: &'a [u8]) -> Result<Self, AtlasError> {
        let atlas = Atlas::parse(bytes)?;
        if atlas.len() > N {
            return Err(AtlasError::TooLarge {
                index: atlas.len().min(u16::MAX as usize) as u16,
                needed: atlas.len() as u32,
            });
        }
        let mut tiles = [None; N];
        for (i, slot) in tiles.iter_mut().enumerate().take(atlas.len()) {
            let index = i as u16;
            let e = atlas.entry(i).ok_or(AtlasError::NoSuchTile { index })?;
            let (o, l) = (e.offset as usize, e.length as usize);
            let b = bytes.get(o..o + l).ok_or(AtlasError::Tile {
                index,
                error: TileError::Truncated {
                    expected: o + l,
                    got: bytes.len(),
                },
            })?;
            *slot = Some(check_tile(&atlas, index, &e, b)?);
        }
        Ok(Self { atlas, tiles })
    }
    /// Tile `index` (already validated).
    pub fn get(&self, index: u16) -> Result<Tile<'a>, AtlasError> {
        self.tiles
            .get(index as usize)
            .copied()
            .flatten()
            .ok_or(AtlasError::NoSuchTile { index })
    }
}

impl<const N: usize> TileSource for MappedAtlas<'_, N> {
    fn atlas(&self) -> &Atlas<'_> {
        &self.atlas
    }
    fn tile(&mut self, index: u16) -> Result<Tile<'_>, AtlasError> {
        self.get(index)
    }
}

impl<const N: usize> TileSource for &MappedAtlas<'_, N> {
    fn atlas(&self) -> &Atlas<'_> {
        &self.atlas
    }
    fn tile(&mut self, index: u16) -> Result<Tile<'_>, AtlasError> {
        self.get(index)
    }
}

/// Random-access reader of the storage an atlas lives in (external flash, a file).
pub trait AtlasRead {
    /// Fill `buf` with the bytes at `offset` from the start of the atlas; `false` on failure.
    fn read_at(&mut self, offset: u32, buf: &mut [u8]) -> bool;
}

impl AtlasRead for &[u8] {
    fn read_at(&mut self, offset: u32, buf: &mut [u8]) -> bool {
        let o = offset as usize;
        let Some(end) = o.checked_add(buf.len()) else {
            return false;
        };
        match self.get(o..end) {
            Some(src) => {
                buf.copy_from_slice(src);
                true
            }
            None => false,
        }
    }
}

/// An atlas whose tiles stay in external storage: the index borrowed from RAM, one tile at a
/// time read through `R` into a caller-given RAM buffer (e.g. a `static` of the size the
/// ground reports as `largest_tile_bytes`) and validated (CRC included) when the navigator
/// switches to it; the frame that switches pays for the read and the checksum.
#[derive(Debug)]
pub struct BufferedAtlas<'a, 'b, R> {
    atlas: Atlas<'a>,
    reader: R,
    buf: &'b mut [u8],
    loaded: Option<u16>,
}

impl<'a, 'b, R: AtlasRead> BufferedAtlas<'a, 'b, R> {
    /// `index` holds (at least) the atlas index; `reader` reads the whole atlas; `buf` holds
    /// one tile (its length bounds the tiles this source can give).
    pub fn new(index: &'a [u8], reader: R, buf: &'b mut [u8]) -> Result<Self, AtlasError> {
        Ok(Self {
            atlas: Atlas::parse(index)?,
            reader,
            buf,
            loaded: None,
        })
    }
    /// The tile currently in the buffer.
    pub fn loaded(&self) -> Option<u16> {
        self.loaded
    }
}

impl<R: AtlasRead> TileSource for BufferedAtlas<'_, '_, R> {
    fn atlas(&self) -> &Atlas<'_> {
        &self.atlas
    }
    fn tile(&mut self, index: u16) -> Result<Tile<'_>, AtlasError> {
        let e = self
            .atlas
            .entry(index as usize)
            .ok_or(AtlasError::NoSuchTile { index })?;
        let len = e.length as usize;
        if len > self.buf.len() {
            return Err(AtlasError::TooLarge {
                index,
                needed: e.length,
            });
        }
        if self.loaded != Some(index) {
            self.loaded = None;
            let dst = self.buf.get_mut(..len).ok_or(AtlasError::Read { index })?;
            if !self.reader.read_at(e.offset, dst) {
                return Err(AtlasError::Read { index });
            }
            // Validate once per load; keep it only if it is sound.
            check_tile(&self.atlas, index, &e, self.buf.get(..len).unwrap_or(&[]))?;
            self.loaded = Some(index);
        }
        check_loaded(self.buf.get(..len).unwrap_or(&[]), index)
    }
}

/// Re-borrow a loaded tile: the buffer passed the full check when it was loaded and only
/// [`BufferedAtlas::tile`] writes it, so the layout is parsed again (no self-referencing
/// handle under `forbid(unsafe_code)`) but the CRC and the features are not.
fn check_loaded(bytes: &[u8], index: u16) -> Result<Tile<'_>, AtlasError> {
    Tile::parse_validated(bytes).map_err(|error| AtlasError::Tile { index, error })
}

/// Errors of [`AtlasNavigator::locate_dem`] that are not "no fix".
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AtlasNavError {
    /// The frame or configuration is unusable.
    Nav(NavError),
    /// A tile could not be had.
    Atlas(AtlasError),
}

impl fmt::Display for AtlasNavError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Nav(e) => write!(f, "{e}"),
            Self::Atlas(e) => write!(f, "{e}"),
        }
    }
}
impl core::error::Error for AtlasNavError {}
impl From<NavError> for AtlasNavError {
    fn from(e: NavError) -> Self {
        Self::Nav(e)
    }
}
impl From<AtlasError> for AtlasNavError {
    fn from(e: AtlasError) -> Self {
        Self::Atlas(e)
    }
}

/// Atlas navigation settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AtlasConfig {
    /// The navigator on each tile.
    pub nav: NavConfig,
    /// Most tiles one frame is located on (1..=[`MAX_ATLAS_CANDIDATES`]). The first try is a
    /// full locate (with the area search); later tries reuse the frame's extraction and run
    /// the feature path and its refinement only, so each costs matching, consensus and
    /// refinement (`docs/bounds.md`).
    pub max_tiles_per_frame: u8,
}

impl Default for AtlasConfig {
    fn default() -> Self {
        Self {
            nav: NavConfig::default(),
            max_tiles_per_frame: crate::flight::ATLAS_TILES_PER_FRAME,
        }
    }
}

/// What one frame on the atlas gave.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AtlasReport {
    /// The tiles ranked for the frame.
    pub candidates: Candidates,
    /// Tiles located on, in order (a prefix of the candidates, less unreadable ones).
    pub tried: u8,
    /// Neighbours skipped because their tile could not be read (a storage fault).
    pub unreadable: u8,
    /// The tile whose report is given: the first that fixed, else the first tried. `None`
    /// when no tile reaches the prior (then `report` is `None` too).
    pub tile: Option<u16>,
    /// Atlas pixel of that tile's pixel (0, 0): add it to the fix's tile pixel coordinates.
    pub tile_offset_px: [i32; 2],
    /// The navigator's report on that tile (fix in that tile's pixels; geo metres as always).
    pub report: Option<FrameReport>,
}

impl AtlasReport {
    /// The fix's frame centre in atlas pixels, if there is a fix.
    pub fn center_atlas_px(&self) -> Option<[f64; 2]> {
        let fix = self.report.as_ref()?.outcome.as_ref().ok()?;
        Some([
            fix.center_tile_px[0] + self.tile_offset_px[0] as f64,
            fix.center_tile_px[1] + self.tile_offset_px[1] as f64,
        ])
    }
}

/// The navigator over an atlas: selects the tile(s) under the prior and locates the frame.
#[derive(Debug, Clone, Copy)]
pub struct AtlasNavigator {
    cfg: AtlasConfig,
}

impl AtlasNavigator {
    /// With settings.
    pub fn new(cfg: AtlasConfig) -> Self {
        Self { cfg }
    }
    /// The settings.
    pub fn config(&self) -> &AtlasConfig {
        &self.cfg
    }

    /// Locate a DEM frame on the atlas under `prior` (atlas pixels; a prior is required: it is
    /// what picks the tile).
    ///
    /// A frame that lies wholly inside the deepest tile (at the prior's centre) is located on
    /// it exactly as on a single tile ([`Navigator::locate_dem`]: with the prior, the area
    /// search first, [`crate::NavConfig::search_first`]); no neighbour could help it. A frame
    /// that hangs over the tile's edge may need a neighbour, which needs its features: it is
    /// extracted once, and on the deepest tile its feature path runs (matching, consensus,
    /// refinement, prior gate: [`Navigator::locate_dem`] without the area search). When that
    /// gives no fix:
    ///
    /// * when it has at least the gate's `min_matches` features (fewer fix on no tile by
    ///   features) and its failure was cheap (no dense refinement ran), the next candidates'
    ///   feature paths follow on the same extraction, up to `max_tiles_per_frame` tiles in
    ///   all, first fix taken;
    /// * else the deepest tile's area search runs.
    ///
    /// (The search first for such frames too cost the HIL set's coast frame its fix: the search
    /// on the deepest tile, which the frame mostly leaves, spent the budget its neighbour's
    /// features needed.) The frame's work is carried over the tiles tried and bounded by the
    /// navigator's work budget ([`crate::NavConfig::work_budget`]): a neighbour's matching,
    /// consensus and refinement, or the search, run only where they fit (docs/bounds.md).
    /// Afterwards the workspace's matches and inlier flags are those of the last tile tried
    /// (which may not be the tile of the returned report).
    pub fn locate_dem<
        S: TileSource,
        const P: usize,
        const W: usize,
        const K: usize,
        const M: usize,
    >(
        &self,
        source: &mut S,
        ws: &mut NavWorkspace<P, W, K, M>,
        dem: &DemPatch<'_>,
        prior: &Prior,
    ) -> Result<AtlasReport, AtlasNavError> {
        let candidates = source.atlas().select(prior, dem.width(), dem.height());
        let mut out = AtlasReport {
            candidates,
            tried: 0,
            unreadable: 0,
            tile: None,
            tile_offset_px: [0, 0],
            report: None,
        };
        let budget = (self.cfg.max_tiles_per_frame as usize).clamp(1, MAX_ATLAS_CANDIDATES);
        let (w, h) = (dem.width(), dem.height());
        let Some(&first) = candidates.as_slice().first() else {
            return Ok(out);
        };
        let e = source
            .atlas()
            .entry(first as usize)
            .ok_or(AtlasError::NoSuchTile { index: first })?;
        let tp = e.tile_prior(prior);
        let hangs_over = candidates.depth_px[0] < candidates.half_diag_px;
        let (k, mut report, neighbours) = {
            let nav = Navigator::new(source.tile(first)?, self.cfg.nav);
            let k = nav.bin_factor(dem.pixel_m());
            if !hangs_over {
                // Wholly inside the deepest tile: no neighbour can help, so exactly the single
                // tile's path (with the prior, the area search first when so configured).
                (k, nav.locate_dem(ws, dem, Some(&tp))?, false)
            } else if let Some(refused) = nav.extract_dem(ws, dem, k)? {
                // Over its edge, but the features do not fit after the slope.
                (k, refused, false)
            } else {
                // Over its edge: the features first, which a neighbour may need.
                let spent = nav.extraction_work(ws);
                let mut report =
                    nav.locate_extracted_dem(ws, (w, h), k, Some(&tp), false, spent)?;
                let neighbours = report.outcome.is_err()
                    && candidates.straddles
                    && candidates.count > 1
                    && budget > 1
                    && report.features >= self.cfg.nav.gate.min_matches
                    && report.refine.is_none();
                if report.outcome.is_err() && !neighbours {
                    nav.area_search_extracted(ws, &mut report, w, h, k, Some(&tp))?;
                }
                (k, report, neighbours)
            }
        };
        out.tried = 1;
        out.tile = Some(first);
        out.tile_offset_px = [e.col0, e.row0];
        // The frame's work and budget verdict over every tile tried.
        let (mut spent, mut over_budget) = (report.work, report.over_budget);
        if neighbours {
            for &index in candidates.as_slice().iter().take(budget).skip(1) {
                let Some(e) = source.atlas().entry(index as usize) else {
                    continue;
                };
                // A neighbour that cannot be read costs this frame that neighbour, not the
                // deepest tile's report.
                let Ok(tile) = source.tile(index) else {
                    out.unreadable += 1;
                    continue;
                };
                let nav = Navigator::new(tile, self.cfg.nav);
                let r = nav.locate_extracted_dem(
                    ws,
                    (w, h),
                    k,
                    Some(&e.tile_prior(prior)),
                    false,
                    spent,
                )?;
                out.tried += 1;
                spent = r.work;
                over_budget |= r.over_budget;
                if r.outcome.is_ok() {
                    out.tile = Some(index);
                    out.tile_offset_px = [e.col0, e.row0];
                    report = r;
                    break;
                }
                // One expensive stage per frame: after a refinement, no further neighbour; and
                // none once the work budget refused a stage.
                if r.refine.is_some() || r.outcome == Err(crate::NoFix::OverBudget) {
                    break;
                }
            }
        }
        report.work = spent;
        report.over_budget = over_budget;
        out.report = Some(report);
        Ok(out)
    }
}

/// Serialise an atlas index for `entries` into `out` (the ground appends the tile blobs at
/// the entries' offsets); returns the bytes written (`atlas_index_len(H, entries.len())` for
/// the encoded header's length `H`; `atlas_index_len(MAX_ATLAS_HEADER_LEN, n)` always
/// suffices). Entries are not checked here: [`Atlas::parse`] checks them.
pub fn write_atlas_index(
    header: &AtlasHeader<'_>,
    entries: &[AtlasEntry],
    out: &mut [u8],
) -> Result<usize, AtlasError> {
    if entries.is_empty() || entries.len() > MAX_ATLAS_TILES {
        return Err(AtlasError::BadHeader);
    }
    if !header.valid() {
        return Err(AtlasError::BadGeometry);
    }
    let mut hbuf = [0u8; MAX_ATLAS_HEADER_LEN];
    let hbytes = postcard::to_slice(header, &mut hbuf).map_err(|_| AtlasError::BadHeader)?;
    let header_len = hbytes.len();
    let total = atlas_index_len(header_len, entries.len());
    let out = out
        .get_mut(..total)
        .ok_or(AtlasError::BufferTooSmall { needed: total })?;
    out.get_mut(ATLAS_PREAMBLE_LEN..ATLAS_PREAMBLE_LEN + header_len)
        .ok_or(AtlasError::BufferTooSmall { needed: total })?
        .copy_from_slice(hbytes);
    fn put(out: &mut [u8], at: usize, bytes: &[u8]) {
        if let Some(dst) = out.get_mut(at..at + bytes.len()) {
            dst.copy_from_slice(bytes);
        }
    }
    put(out, 0, &ATLAS_MAGIC);
    put(out, 8, &ATLAS_FORMAT_VERSION.to_le_bytes());
    put(out, 10, &(header_len as u16).to_le_bytes());
    put(out, 12, &(entries.len() as u32).to_le_bytes());
    let e_start = align4(ATLAS_PREAMBLE_LEN + header_len);
    let pad = e_start - ATLAS_PREAMBLE_LEN - header_len;
    put(
        out,
        ATLAS_PREAMBLE_LEN + header_len,
        [0u8; 3].get(..pad).unwrap_or(&[]),
    );
    for (i, e) in entries.iter().enumerate() {
        let at = e_start + i * ATLAS_ENTRY_LEN;
        put(out, at, &e.col0.to_le_bytes());
        put(out, at + 4, &e.row0.to_le_bytes());
        put(out, at + 8, &e.width.to_le_bytes());
        put(out, at + 12, &e.height.to_le_bytes());
        put(out, at + 16, &e.offset.to_le_bytes());
        put(out, at + 20, &e.length.to_le_bytes());
        put(out, at + 24, &e.crc.to_le_bytes());
    }
    let crc = CRC.checksum(out.get(..total - 4).unwrap_or(&[]));
    put(out, total - 4, &crc.to_le_bytes());
    Ok(total)
}
