//! Large maps in blocks: the scene is cut into overlapping blocks on the output grid, each block
//! simulated, focused, unwrapped and geocoded on its own (memory bounded by the block, whatever
//! the scene), written to `OUT/blocks/block-NNN/`, then mosaicked onto the map grid.
//!
//! One pass, one track: every block is seen from the track placed for the whole scene
//! ([`crate::sar::pipeline::SceneFrame`]), and each facet draws its speckle by its place in the
//! whole scene's mesh, so two blocks see their common ground alike. Each block takes its own
//! mean height as the processing datum (as a processor with a coarse prior DEM would) and its
//! own thermal noise. Blocks are pure functions of (DEM, settings, index): run in one process
//! or as `--block i/N` on many machines, the block files are the same bytes, and the mosaic
//! reads them back either way, so its products are too.
//!
//! Blend: core blocks tile the grid; each is widened by `overlap_cells` on every side. Across an
//! overlap the outer half of each block's margin counts nothing (its edge effects: partial
//! multilook windows, ground beyond the block that would shadow or fold onto it), and the
//! middle `overlap_cells` ramp linearly from one block to the other (weights sum to 1). A cell's
//! mask code is the code of its heaviest block; a valid cell's height, coherence and height
//! bound are the weighted mean over the blocks valid there, unless those blocks disagree by
//! whole cycles (their unwrappings took different 2π multiples), when the cell is dropped.
//! Seams are checked: the height difference of overlapping blocks where both are valid, and
//! whole-cycle disagreements.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail, ensure};
use serde::{Deserialize, Serialize};

use super::accuracy::window_truth;
use super::baselines::BaselineFusion;
use super::cycles::coarse_prior;
use super::geocode::{OutputGrid, label};
use super::geometry::PairGeometry;
use super::pipeline::{
    CoregReport, InsarConfig, InsarProduct, LookDirections, LookFusion, MaskFractions, RadarLayers,
    TruthOnGrid, UnwrapReport, fuse_looks, mirrored_dem, pass_noise_seed, process_stack, slc_pairs,
    stack_timings,
};
use super::products::SarSummary;
use crate::dem::{Dem, SampleKind, read_geotiff, write_geotiff};
use crate::sar::pipeline::{MeshOffset, SceneFrame, SimOptions, Timings, simulate_with};
use crate::sar::scattering::splitmix64;
use crate::sar::{Antenna, Polarisation, SarConfig, SarDem};

/// Core block side, output cells, of `insar` by default: 400 cells = 8 km at 20 m. A 16 km map
/// is 4 blocks; a block with its margins (9 km at the 5 m radar mesh) peaks near 1 GiB.
pub const DEFAULT_BLOCK_CELLS: usize = 400;
/// Margin added to each side of a block, output cells (500 m at 20 m): covers the multilook
/// window, the geocoding's edge extension and its 8-pixel search, and the fold of walls up to
/// ≈ 250 m high at 26° incidence.
pub const DEFAULT_OVERLAP_CELLS: usize = 25;
/// Version of the block files (`block.json`). 2: the height CRLB layer follows the DEM
/// filter (`pipeline::dem_filter_noise_factor`), and the record carries that factor. 3: the
/// DEM filter may be the local quadratic fit (`pipeline::DemFilterKind`, in the record's
/// configuration), and the record carries the filtered noise's correlation length. 4: the
/// configuration may give the long pair its own filter width, and the long baseline's record
/// carries it (blocks of version 3 would be refused as made with other settings).
pub const BLOCK_FORMAT_VERSION: u32 = 4;
/// Folder of the block products inside an `insar` output folder.
pub const BLOCKS_DIR: &str = "blocks";
const BLOCK_JSON: &str = "block.json";
const DEM_TIF: &str = "dem.tif";
const COHERENCE_TIF: &str = "coherence.tif";
const CRLB_TIF: &str = "height-crlb.tif";
const MASK_TIF: &str = "mask.tif";

/// A half-open rectangle of output cells: rows `row0..row1`, columns `col0..col1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellRect {
    /// First row.
    pub row0: usize,
    /// One past the last row.
    pub row1: usize,
    /// First column.
    pub col0: usize,
    /// One past the last column.
    pub col1: usize,
}

impl CellRect {
    /// Columns.
    pub fn width(&self) -> usize {
        self.col1 - self.col0
    }
    /// Rows.
    pub fn height(&self) -> usize {
        self.row1 - self.row0
    }
    /// Whether cell `(row, col)` is inside.
    pub fn contains(&self, row: usize, col: usize) -> bool {
        (self.row0..self.row1).contains(&row) && (self.col0..self.col1).contains(&col)
    }
}

/// How a map grid is cut into blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BlockLayout {
    /// Map grid columns, output cells.
    pub grid_width: usize,
    /// Map grid rows, output cells.
    pub grid_height: usize,
    /// Largest core block side, cells.
    pub block_cells: usize,
    /// Margin on each side of a core block, cells.
    pub overlap_cells: usize,
    /// Block rows.
    pub rows: usize,
    /// Block columns.
    pub cols: usize,
}

/// One block: its index, core (the cells it owns) and extent (core plus margins, clipped to
/// the grid).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BlockSpec {
    /// Row-major index, `0..count`.
    pub index: usize,
    /// Cells the block owns.
    pub core: CellRect,
    /// Cells the block computes.
    pub extent: CellRect,
}

impl BlockLayout {
    /// Cut a `grid_width × grid_height` grid into core blocks of at most `block_cells` per side
    /// (as equal as whole cells allow), widened by `overlap_cells`.
    pub fn new(
        grid_width: usize,
        grid_height: usize,
        block_cells: usize,
        overlap_cells: usize,
    ) -> anyhow::Result<Self> {
        ensure!(
            grid_width > 0 && grid_height > 0,
            "empty grid {grid_width}×{grid_height}"
        );
        ensure!(
            block_cells >= 2 * overlap_cells.max(8),
            "block side {block_cells} cells must be at least twice the overlap ({overlap_cells}) and 16"
        );
        Ok(Self {
            grid_width,
            grid_height,
            block_cells,
            overlap_cells,
            rows: grid_height.div_ceil(block_cells),
            cols: grid_width.div_ceil(block_cells),
        })
    }

    /// Number of blocks.
    pub fn count(&self) -> usize {
        self.rows * self.cols
    }

    fn bound(n: usize, parts: usize, i: usize) -> usize {
        // Equal splits rounded to whole cells: exact integer arithmetic, same on every machine.
        (i * n + parts / 2) / parts.max(1)
    }

    /// Block `index` (row-major), or an error naming the valid range.
    pub fn block(&self, index: usize) -> anyhow::Result<BlockSpec> {
        ensure!(
            index < self.count(),
            "block {index} out of range: this map has {} blocks (0..{})",
            self.count(),
            self.count()
        );
        let (br, bc) = (index / self.cols, index % self.cols);
        let core = CellRect {
            row0: Self::bound(self.grid_height, self.rows, br),
            row1: Self::bound(self.grid_height, self.rows, br + 1),
            col0: Self::bound(self.grid_width, self.cols, bc),
            col1: Self::bound(self.grid_width, self.cols, bc + 1),
        };
        let o = self.overlap_cells;
        let extent = CellRect {
            row0: core.row0.saturating_sub(o),
            row1: (core.row1 + o).min(self.grid_height),
            col0: core.col0.saturating_sub(o),
            col1: (core.col1 + o).min(self.grid_width),
        };
        Ok(BlockSpec {
            index,
            core,
            extent,
        })
    }

    /// Every block in index order.
    pub fn blocks(&self) -> Vec<BlockSpec> {
        (0..self.count())
            .filter_map(|i| self.block(i).ok())
            .collect()
    }

    /// Blend weight of `spec` at cell `(row, col)`, 0–1 (see the module docs); the weights of
    /// all blocks at a cell sum to 1.
    pub fn weight(&self, spec: &BlockSpec, row: usize, col: usize) -> f64 {
        if !spec.extent.contains(row, col) {
            return 0.0;
        }
        let half = 0.5 * self.overlap_cells as f64;
        // Ramp up across a lower boundary `a` (if a neighbour lies below it), down across an
        // upper boundary `b` (if one lies above it); cell centres at x + 0.5.
        let axis = |x: usize, a: usize, b: usize, n: usize| -> f64 {
            let xc = x as f64 + 0.5;
            let up = |edge: usize| {
                if half == 0.0 {
                    if xc >= edge as f64 { 1.0 } else { 0.0 }
                } else {
                    ((xc - (edge as f64 - half)) / (2.0 * half)).clamp(0.0, 1.0)
                }
            };
            let lo = if a > 0 { up(a) } else { 1.0 };
            let hi = if b < n { 1.0 - up(b) } else { 1.0 };
            lo.min(hi)
        };
        axis(row, spec.core.row0, spec.core.row1, self.grid_height)
            * axis(col, spec.core.col0, spec.core.col1, self.grid_width)
    }
}

/// What one block run records beside its rasters (`block.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BlockRecord {
    /// [`BLOCK_FORMAT_VERSION`].
    pub version: u32,
    /// Digest of everything that decides the block (input DEM, radar, processing, layout): the
    /// mosaic joins only blocks with the same digest.
    pub digest: String,
    /// The layout.
    pub layout: BlockLayout,
    /// This block.
    pub block: BlockSpec,
    /// The pair geometry of the block (its own datum; the one track of the scene).
    pub geometry: PairGeometry,
    /// Side of the square the multilook window covers on the ground, m.
    pub window_side_m: f64,
    /// Equivalent looks of one window, times the stacked passes.
    pub effective_looks: f64,
    /// Factor the DEM filter shrank the height CRLB by (`InsarProduct::crlb_filter_factor`).
    pub crlb_filter_factor: f64,
    /// Correlation length of the filtered height noise, m (`InsarProduct::error_blur_m`).
    pub error_blur_m: f64,
    /// Coregistration figures.
    pub coreg: CoregReport,
    /// Unwrapping figures.
    pub unwrap: UnwrapReport,
    /// Mask fractions over the block's extent.
    pub mask: MaskFractions,
    /// Cells removed by eq 20.
    pub eq20_removed: usize,
    /// Cells removed by the ray-traced geometry.
    pub geometry_removed: usize,
    /// Mean coherence of the block's radar pixels.
    pub coherence_mean_radar: f64,
    /// SAR simulation timings of the block.
    pub sar_timings: Timings,
    /// Facets in the block's mesh / shadowed / layover.
    pub facets: [usize; 3],
    /// Nodata heights of the whole input filled before simulating.
    pub filled_nodata: usize,
    /// InSAR processing time, s.
    pub insar_s: f64,
    /// With both look directions: how the block's two passes were fused.
    pub look_fusion: Option<LookFusion>,
    /// With a long baseline: how it entered the block's map, per look (east first).
    #[serde(default)]
    pub baseline_fusion: Vec<BaselineFusion>,
}

/// Settings of a blocked run, shared by every block.
#[derive(Debug, Clone)]
pub struct BlockJob<'a> {
    /// The whole scene DEM (north-up, square pixels; the output pixel a whole multiple of it).
    pub truth: &'a Dem,
    /// Radar configuration (the InSAR channel only).
    pub sar: &'a SarConfig,
    /// The InSAR channel.
    pub pol: Polarisation,
    /// Processing.
    pub cfg: &'a InsarConfig,
    /// Block layout.
    pub layout: BlockLayout,
    /// Output folder (blocks go to `OUT/blocks/`).
    pub out: &'a Path,
    /// Show the SAR progress bars.
    pub progress: bool,
    /// One pass (east-looking) or both (each block also seen looking west, then fused).
    pub looks: LookDirections,
}

/// The layout of `truth` mapped at `cfg.pixel_m`, or `None` when the map fits one block.
pub fn layout_for(
    truth: &Dem,
    pixel_m: f64,
    block_cells: usize,
    overlap_cells: usize,
) -> anyhow::Result<Option<BlockLayout>> {
    if block_cells == 0 {
        return Ok(None);
    }
    let k = cells_per_pixel(truth, pixel_m)?;
    let (w, h) = (truth.width() / k, truth.height() / k);
    if w <= block_cells && h <= block_cells {
        return Ok(None);
    }
    BlockLayout::new(w, h, block_cells, overlap_cells).map(Some)
}

/// Input pixels per output cell side: blocks need a whole number (the output cell is the block
/// mean of the input pixels it covers, so a block's cells equal the whole map's).
fn cells_per_pixel(truth: &Dem, pixel_m: f64) -> anyhow::Result<usize> {
    let p = truth.pixel_m()?;
    let ratio = pixel_m / p;
    let k = ratio.round();
    ensure!(
        (ratio - k).abs() < 1e-9 && k >= 1.0,
        "a map in blocks needs an output pixel that is a whole multiple of the DEM pixel \
         ({pixel_m} m over {p} m); resample the DEM (`ground-sim resample`) or pick --pixel-m"
    );
    Ok(k as usize)
}

/// Digest of a blocked run's inputs and settings.
pub fn digest(job: &BlockJob<'_>) -> anyhow::Result<String> {
    const CRC64: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);
    let mut d = CRC64.digest();
    for v in job.truth.heights_m() {
        d.update(&v.to_le_bytes());
    }
    d.update(format!("{:?}", job.truth.geo.transform.0).as_bytes());
    d.update(serde_json::to_string(job.sar)?.as_bytes());
    d.update(job.pol.tag().as_bytes());
    d.update(serde_json::to_string(job.cfg)?.as_bytes());
    d.update(serde_json::to_string(&job.layout)?.as_bytes());
    d.update(job.looks.name().as_bytes());
    Ok(format!("{:016x}", d.finalize()))
}

/// Folder of block `index`.
pub fn block_dir(out: &Path, index: usize) -> PathBuf {
    out.join(BLOCKS_DIR).join(format!("block-{index:03}"))
}

/// One look's pass over a block: the product on the block's grid and the SAR figures.
struct BlockPass {
    product: InsarProduct,
    window_side_m: f64,
    timings: Timings,
    facets: [usize; 3],
    filled: usize,
}

/// Simulate and process the input-pixel rectangle `(r0, c0, w, h)` of `scene` (the whole scene,
/// or its mirror for the west-looking pass) as one block seen from the scene's track.
fn run_pass(
    job: &BlockJob<'_>,
    scene: &Dem,
    rect: [usize; 4],
    noise_seed: u64,
    what: &str,
) -> anyhow::Result<BlockPass> {
    let [r0, c0, w, h] = rect;
    let p = scene.pixel_m()?;
    // The whole scene in the radar's frame, nodata filled once for all blocks alike.
    let (whole, filled) = SarDem::from_dem(scene)?;
    let centre = [
        0.5 * (whole.height - 1) as f64 * p,
        0.5 * (whole.width - 1) as f64 * p,
        whole.mean_height_m(),
    ];
    let sdem = whole.crop(r0, c0, w, h)?;
    let origin = sdem.origin_m;
    drop(whole);
    // The block mesh on the scene mesh's lattice when the mesh divides the DEM pixel.
    let mesh_offset = MeshOffset::for_block(p, job.sar.mesh_spacing_m, r0, c0, scene.width());
    // The passes of one track with `radar`, pass k's receiver noise seeded by `noise(k)` (None:
    // the block's own seed).
    let fly = |radar: &SarConfig, noise: &dyn Fn(usize) -> Option<u64>, pair: &str| {
        (0..job.cfg.passes.max(1))
            .map(|k| {
                let opts = SimOptions {
                    progress: job.progress,
                    scene: Some(SceneFrame {
                        centre_m: centre,
                        mesh_offset,
                        noise_seed,
                    }),
                    noise_seed: noise(k),
                    ..SimOptions::default()
                };
                simulate_with(&sdem, radar, &opts)
                    .with_context(|| format!("simulating {what}{pair}"))
            })
            .collect::<anyhow::Result<Vec<_>>>()
    };
    // Stacked passes of the track: the block's own noise seed first, then one per pass.
    let passes = fly(
        job.sar,
        &|k| (k > 0).then(|| pass_noise_seed(noise_seed, k)),
        "",
    )?;
    // The long pair, if any: the same ground through its own receivers.
    let long_passes = if job.cfg.long_baseline_m > 0.0 {
        let long_sar = crate::insar::baselines::long_radar(job.sar, job.cfg.long_baseline_m);
        let seed = |k| Some(crate::insar::baselines::long_noise_seed(noise_seed, k));
        fly(&long_sar, &seed, ", long baseline")?
    } else {
        Vec::new()
    };
    drop(sdem);
    let pairs = slc_pairs(&passes, job.pol)?;
    let pair = &passes[0];
    let slc = |a: Antenna| {
        pair.slc(a, job.pol)
            .ok_or_else(|| anyhow::anyhow!("no {a:?} {} SLC", job.pol.tag()))
    };
    let sub_truth = scene.crop_px(c0, r0, w, h)?;
    let truth_grid = crate::reference::reference_dem(&sub_truth, job.cfg.pixel_m)?;
    let mut grid = OutputGrid::aligned(&sub_truth, &truth_grid)?;
    grid.x0_m += origin[0];
    grid.y0_m += origin[1];
    let prior = (job.cfg.prior_dem_cell_m > 0.0)
        .then(|| coarse_prior(&truth_grid, job.cfg.prior_dem_cell_m));
    let mut product = process_stack(&pairs, &grid, job.cfg, prior.as_deref())
        .with_context(|| format!("processing {what}"))?;
    let mut timings = stack_timings(&passes);
    if !long_passes.is_empty() {
        crate::insar::baselines::add_long_baseline(
            &mut product,
            &slc_pairs(&long_passes, job.pol)?,
            prior.as_deref(),
            job.cfg,
        )
        .with_context(|| format!("processing {what}, long baseline"))?;
        timings += &stack_timings(&long_passes);
    }
    let (a1, g) = (slc(Antenna::A1)?, &product.geometry);
    let n = job.cfg.window.size as f64;
    let centre_r = g.range_m(0.5 * (a1.gates as f64 - 1.0));
    let window_side_m = 0.5
        * (n * g.azimuth_spacing_m + n * g.range_spacing_m / g.flat_look_angle_rad(centre_r).sin());
    Ok(BlockPass {
        product,
        window_side_m,
        // Every stacked pass's time (and the long pair's); the facet counts are the track's
        // (the same per pass).
        timings,
        facets: [pair.stats.facets, pair.stats.shadowed, pair.stats.layover],
        filled,
    })
}

/// Simulate and process block `index` of `job` (with [`LookDirections::Both`], also the
/// west-looking pass over the mirrored scene, fused cell by cell as in one piece); write its
/// rasters and `block.json` into [`block_dir`]. Returns the record.
pub fn run_block(job: &BlockJob<'_>, index: usize) -> anyhow::Result<BlockRecord> {
    crate::insar::pipeline::check_long_baseline(job.sar, job.cfg)?;
    let spec = job.layout.block(index)?;
    let k = cells_per_pixel(job.truth, job.cfg.pixel_m)?;
    let e = spec.extent;
    let (r0, c0, w, h) = (e.row0 * k, e.col0 * k, e.width() * k, e.height() * k);
    let seed = |look: u64| splitmix64(job.sar.seed ^ splitmix64(index as u64 + 1 + (look << 32)));
    let mut east = run_pass(
        job,
        job.truth,
        [r0, c0, w, h],
        seed(0),
        &format!("block {index}"),
    )?;
    let mut look_fusion = None;
    if job.looks == LookDirections::Both {
        // The same block of the mirrored scene: its columns reversed are this block's.
        let mirrored = mirrored_dem(job.truth)?;
        let mc0 = job.truth.width() - (c0 + w);
        let west = run_pass(
            job,
            &mirrored,
            [r0, mc0, w, h],
            seed(1),
            &format!("block {index}, west-looking pass"),
        )?;
        look_fusion = Some(fuse_looks(&mut east.product, &west.product)?);
        east.timings += &west.timings;
        for (a, b) in east.facets.iter_mut().zip(west.facets) {
            *a += b;
        }
    }
    let BlockPass {
        product,
        window_side_m,
        timings,
        facets,
        filled,
    } = east;
    let record = BlockRecord {
        version: BLOCK_FORMAT_VERSION,
        digest: digest(job)?,
        layout: job.layout,
        block: spec,
        geometry: product.geometry,
        window_side_m,
        effective_looks: product.effective_looks,
        crlb_filter_factor: product.crlb_filter_factor,
        error_blur_m: product.error_blur_m,
        coreg: product.coreg,
        unwrap: product.unwrap,
        mask: product.mask,
        eq20_removed: product.eq20_removed,
        geometry_removed: product.geometry_removed,
        coherence_mean_radar: product.coherence_mean_radar,
        sar_timings: timings,
        facets,
        filled_nodata: filled,
        insar_s: product.seconds,
        look_fusion,
        baseline_fusion: product.baseline_fusion.clone(),
    };
    let dir = block_dir(job.out, index);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let tif = |dem: &Dem, name: &str, kind: SampleKind| {
        write_geotiff(dem, &dir.join(name), Some(kind))
            .with_context(|| format!("writing {}", dir.join(name).display()))
    };
    tif(&product.dem, DEM_TIF, SampleKind::F32)?;
    tif(&product.coherence, COHERENCE_TIF, SampleKind::F32)?;
    tif(&product.crlb_m, CRLB_TIF, SampleKind::F32)?;
    let mask = product
        .grid
        .raster(product.labels.iter().map(|&l| f32::from(l)).collect())?;
    tif(&mask, MASK_TIF, SampleKind::U16)?;
    let text = serde_json::to_string_pretty(&record)? + "\n";
    std::fs::write(dir.join(BLOCK_JSON), text)
        .with_context(|| format!("writing {}", dir.join(BLOCK_JSON).display()))?;
    Ok(record)
}

/// A block read back: its record and rasters over its extent.
struct BlockProduct {
    record: BlockRecord,
    dem: Vec<f32>,
    coherence: Vec<f32>,
    crlb: Vec<f32>,
    labels: Vec<u8>,
}

fn read_block(
    out: &Path,
    index: usize,
    count: usize,
    digest: &str,
) -> anyhow::Result<BlockProduct> {
    let dir = block_dir(out, index);
    let path = dir.join(BLOCK_JSON);
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "block {index} missing ({}): make it first with `insar --block {index}/{count}` \
             and the same flags",
            path.display()
        )
    })?;
    // The version first: an older block lacks fields, and "missing field" would hide why.
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("reading {}", path.display()))?;
    let version = value["version"].as_u64();
    ensure!(
        version == Some(u64::from(BLOCK_FORMAT_VERSION)),
        "{}: block format {} (this build reads {BLOCK_FORMAT_VERSION}): rerun that block",
        path.display(),
        version.map_or("unknown".into(), |v| v.to_string())
    );
    let record: BlockRecord =
        serde_json::from_value(value).with_context(|| format!("reading {}", path.display()))?;
    ensure!(
        record.digest == digest,
        "{}: made from another DEM or other settings (digest {} ≠ {digest}); rerun that block",
        path.display(),
        record.digest
    );
    ensure!(
        record.block.index == index,
        "{}: holds block {}",
        path.display(),
        record.block.index
    );
    let (w, h) = (record.block.extent.width(), record.block.extent.height());
    let raster = |name: &str| -> anyhow::Result<Vec<f32>> {
        let p = dir.join(name);
        let d = read_geotiff(&p).with_context(|| format!("reading {}", p.display()))?;
        ensure!(
            d.width() == w && d.height() == h,
            "{}: {}×{} cells, the block is {w}×{h}",
            p.display(),
            d.width(),
            d.height()
        );
        Ok(d.into_heights())
    };
    let labels = raster(MASK_TIF)?
        .iter()
        .map(|&v| {
            if v.is_finite() {
                v as u8
            } else {
                label::OUTSIDE
            }
        })
        .collect();
    Ok(BlockProduct {
        dem: raster(DEM_TIF)?,
        coherence: raster(COHERENCE_TIF)?,
        crlb: raster(CRLB_TIF)?,
        labels,
        record,
    })
}

/// How the blocks joined (in `report.json` under `blocks`).
#[derive(Debug, Clone, Serialize)]
pub struct MosaicReport {
    /// The layout.
    pub layout: BlockLayout,
    /// Cells where two blocks overlap and both are valid.
    pub overlap_cells_compared: usize,
    /// RMS height difference between overlapping blocks there, m.
    pub overlap_height_diff_rms_m: f64,
    /// Largest |difference| there, m.
    pub overlap_height_diff_max_m: f64,
    /// Cells where overlapping blocks differ by more than half a height of ambiguity (a
    /// whole-cycle disagreement between their unwrappings).
    pub overlap_cycle_disagreements: usize,
    /// Map cells dropped (masked as low coherence) because the blocks that weigh there
    /// disagree by whole cycles.
    pub cells_dropped_for_cycles: usize,
    /// Mosaic height RMSE against the truth in the blend zones (cells more than one block
    /// weighs), m.
    pub height_rmse_blend_zone_m: f64,
    /// The same elsewhere, m.
    pub height_rmse_elsewhere_m: f64,
    /// Valid cells in the blend zones / elsewhere.
    pub valid_cells: [usize; 2],
    /// Per block: index, valid fraction of its extent, unwrapping cycles changed, SAR seconds.
    pub per_block: Vec<BlockLine>,
    /// Peak resident memory of this process, MiB (Linux `VmHWM`; `None` elsewhere).
    pub peak_rss_mib: Option<f64>,
}

/// One block's line in [`MosaicReport::per_block`].
#[derive(Debug, Clone, Serialize)]
pub struct BlockLine {
    /// Block index.
    pub index: usize,
    /// Valid fraction of its extent.
    pub valid: f64,
    /// Unwrapped pixels changed by a whole cycle.
    pub unwrap_pixels_changed: usize,
    /// Its datum (mean height), m.
    pub datum_m: f64,
    /// SAR simulation time, s.
    pub sar_s: f64,
    /// With both looks: whole cycles its west pass was shifted by to align on the east pass.
    pub west_cycles_shifted: Option<i64>,
}

/// Peak resident set of this process, MiB (Linux only).
pub fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// A blocked map joined: the truth on the map grid, the product (radar-geometry layers empty:
/// they belong to single blocks) and the mosaic figures, with the SAR summary of all blocks.
pub struct Mosaic {
    /// The truth on the output grid.
    pub truth: TruthOnGrid,
    /// The joined product.
    pub product: InsarProduct,
    /// Seams and per-block figures.
    pub report: MosaicReport,
    /// SAR summary over all blocks (timings and facets summed).
    pub sar: SarSummary,
    /// Nodata heights filled in the input.
    pub filled_nodata: usize,
}

/// The blocks' long-baseline figures per look, weighted by their core cells (the median
/// bounds too: a weighted mean of the medians of the blocks that gave long cells). Empty when
/// a block has none.
fn fused_baselines(blocks: &[BlockProduct]) -> Vec<BaselineFusion> {
    let Some(first) = blocks.first() else {
        return Vec::new();
    };
    let looks = first.record.baseline_fusion.len();
    if blocks
        .iter()
        .any(|b| b.record.baseline_fusion.len() != looks)
    {
        return Vec::new();
    }
    (0..looks)
        .map(|k| {
            let parts: Vec<(f64, BaselineFusion)> = blocks
                .iter()
                .map(|b| {
                    let e = b.record.block.core;
                    ((e.width() * e.height()) as f64, b.record.baseline_fusion[k])
                })
                .collect();
            let total: f64 = parts.iter().map(|(n, _)| n).sum();
            let mean = |f: &dyn Fn(&BaselineFusion) -> f64| {
                parts.iter().map(|(n, l)| n * f(l)).sum::<f64>() / total.max(1.0)
            };
            BaselineFusion {
                long_baseline_m: first.record.baseline_fusion[k].long_baseline_m,
                long_ambiguity_height_m: mean(&|l| l.long_ambiguity_height_m),
                long_mask: MaskFractions {
                    valid: mean(&|l| l.long_mask.valid),
                    layover: mean(&|l| l.long_mask.layover),
                    shadow: mean(&|l| l.long_mask.shadow),
                    low_coherence: mean(&|l| l.long_mask.low_coherence),
                    outside: mean(&|l| l.long_mask.outside),
                },
                long_share: mean(&|l| l.long_share),
                inconsistent: mean(&|l| l.inconsistent),
                unverifiable: mean(&|l| l.unverifiable),
                // Over the blocks that gave long cells (both medians or neither).
                median_bound_m: weighted(&parts, |l| l.median_bound_m.map(|m| m[0]))
                    .zip(weighted(&parts, |l| l.median_bound_m.map(|m| m[1])))
                    .map(|(a, b)| [a, b]),
                // The filter's variance mixes linearly: the blocks' root mean square σ.
                long_filter_sigma_px: weighted(&parts, |l| l.long_filter_sigma_px.map(|s| s * s))
                    .map(f64::sqrt),
                long_crlb_filter_factor: weighted(&parts, |l| l.long_crlb_filter_factor),
            }
        })
        .collect()
}

/// Cell-weighted mean of `f` over the blocks that have it; `None` if none has.
fn weighted(
    parts: &[(f64, BaselineFusion)],
    f: impl Fn(&BaselineFusion) -> Option<f64>,
) -> Option<f64> {
    let with: Vec<(f64, f64)> = parts
        .iter()
        .filter_map(|(n, l)| f(l).map(|v| (*n, v)))
        .collect();
    let w: f64 = with.iter().map(|(n, _)| n).sum();
    (w > 0.0).then(|| with.iter().map(|(n, v)| n * v).sum::<f64>() / w)
}

/// The blocks' look fusions as one, each block weighted by the cells it owns (its core: the
/// cores tile the map once, so the map's fractions are not skewed by the margins that
/// neighbouring blocks share). Each block's fractions are over its whole extent, so the result
/// approximates the mosaic's own fractions.
fn fused_looks(blocks: &[BlockProduct]) -> Option<LookFusion> {
    let parts: Vec<(f64, LookFusion)> = blocks
        .iter()
        .map(|b| {
            let e = b.record.block.core;
            b.record
                .look_fusion
                .map(|f| ((e.width() * e.height()) as f64, f))
        })
        .collect::<Option<_>>()?;
    let total: f64 = parts.iter().map(|(n, _)| n).sum();
    let mean = |f: &dyn Fn(&LookFusion) -> f64| {
        parts.iter().map(|(n, l)| n * f(l)).sum::<f64>() / total.max(1.0)
    };
    let mask = |f: &dyn Fn(&LookFusion) -> MaskFractions| MaskFractions {
        valid: mean(&|l| f(l).valid),
        layover: mean(&|l| f(l).layover),
        shadow: mean(&|l| f(l).shadow),
        low_coherence: mean(&|l| f(l).low_coherence),
        outside: mean(&|l| f(l).outside),
    };
    Some(LookFusion {
        east_mask: mask(&|l| l.east_mask),
        west_mask: mask(&|l| l.west_mask),
        both_valid: mean(&|l| l.both_valid),
        east_only: mean(&|l| l.east_only),
        west_only: mean(&|l| l.west_only),
        inconsistent: mean(&|l| l.inconsistent),
        // Each block aligns its own looks (its shift is in `blocks.per_block`); the map's
        // figure is how many blocks needed it (documented on the field).
        west_cycles_shifted: parts
            .iter()
            .filter(|(_, l)| l.west_cycles_shifted != 0)
            .count() as i64,
        // The worst window of any block (windows across block edges are not scanned).
        worst_window_one_look_share: parts
            .iter()
            .map(|(_, l)| l.worst_window_one_look_share)
            .filter(|v| v.is_finite())
            .fold(f64::NAN, f64::max),
        // Per octave, the blocks' ratios weighted by their cells (the blocks that measured
        // one); none if no block did.
        error_spectrum_ratio: {
            let with: Vec<(f64, [f64; crate::dem::spectrum::BAND_EDGES.len()])> = parts
                .iter()
                .filter_map(|(n, l)| l.error_spectrum_ratio.map(|r| (*n, r)))
                .collect();
            let total: f64 = with.iter().map(|(n, _)| n).sum();
            (total > 0.0).then(|| {
                core::array::from_fn(|b| with.iter().map(|(n, r)| n * r[b]).sum::<f64>() / total)
            })
        },
    })
}

/// Join the blocks of `job` found in `OUT/blocks/` (all of them must be there, made from the
/// same DEM and settings).
pub fn mosaic(job: &BlockJob<'_>) -> anyhow::Result<Mosaic> {
    let layout = job.layout;
    let digest = digest(job)?;
    let blocks: Vec<BlockProduct> = (0..layout.count())
        .map(|i| read_block(job.out, i, layout.count(), &digest))
        .collect::<anyhow::Result<_>>()?;
    let truth_grid = crate::reference::reference_dem(job.truth, job.cfg.pixel_m)?;
    let (gw, gh) = (truth_grid.width(), truth_grid.height());
    if (gw, gh) != (layout.grid_width, layout.grid_height) {
        bail!(
            "the map grid is {gw}×{gh} cells, the blocks were cut for {}×{}",
            layout.grid_width,
            layout.grid_height
        );
    }
    let grid = OutputGrid::aligned(job.truth, &truth_grid)?;
    let n = gw * gh;
    let mut dem = vec![f32::NAN; n];
    let mut coh = vec![f32::NAN; n];
    let mut sig = vec![f32::NAN; n];
    let mut labels = vec![label::OUTSIDE; n];
    let mut blend_zone = vec![false; n];
    let (mut diff_ss, mut diff_max, mut compared, mut cycles) = (0.0f64, 0.0f64, 0usize, 0usize);
    let mut dropped = 0usize;
    for row in 0..gh {
        for col in 0..gw {
            let i = row * gw + col;
            let mut best: Option<(f64, usize)> = None;
            let mut weighed = 0;
            // (weight, height, coherence, bound, datum's ambiguity) of blocks valid here.
            let mut valid: Vec<(f64, f32, f32, f32, f64)> = Vec::new();
            for (b, blk) in blocks.iter().enumerate() {
                let e = blk.record.block.extent;
                if !e.contains(row, col) {
                    continue;
                }
                let j = (row - e.row0) * e.width() + (col - e.col0);
                let wgt = layout.weight(&blk.record.block, row, col);
                let ok = blk.labels[j] == label::VALID && blk.dem[j].is_finite();
                if ok {
                    let hoa = blk.record.unwrap.ambiguity_height_m;
                    for &(_, h2, _, _, hoa2) in &valid {
                        let d = f64::from(blk.dem[j]) - f64::from(h2);
                        diff_ss += d * d;
                        diff_max = diff_max.max(d.abs());
                        compared += 1;
                        if d.abs() > 0.25 * (hoa + hoa2) {
                            cycles += 1;
                        }
                    }
                    valid.push((wgt, blk.dem[j], blk.coherence[j], blk.crlb[j], hoa));
                }
                if wgt > 0.0 {
                    weighed += 1;
                    if best.is_none_or(|(bw, _)| wgt > bw) {
                        best = Some((wgt, b));
                    }
                }
            }
            blend_zone[i] = weighed > 1;
            let Some((_, b)) = best else { continue };
            let blk = &blocks[b];
            let e = blk.record.block.extent;
            let j = (row - e.row0) * e.width() + (col - e.col0);
            labels[i] = blk.labels[j];
            if labels[i] != label::VALID {
                continue;
            }
            // Blocks that weigh here and disagree by whole cycles: a mean would be wrong by a
            // fraction of a cycle that no mask shows, and which one is right is not known here,
            // so neither is kept (as two looks that disagree, `fuse_looks`).
            let weighing: Vec<_> = valid.iter().filter(|v| v.0 > 0.0).collect();
            let split = weighing.iter().enumerate().any(|(m, a)| {
                weighing[m + 1..]
                    .iter()
                    .any(|b| (f64::from(a.1) - f64::from(b.1)).abs() > 0.25 * (a.4 + b.4))
            });
            if split {
                labels[i] = label::LOW_COHERENCE;
                dropped += 1;
                continue;
            }
            let (mut sw, mut sh, mut sc, mut ss) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for &&(wgt, h, c, s, _) in &weighing {
                sw += wgt;
                sh += wgt * f64::from(h);
                sc += wgt * f64::from(c);
                ss += wgt * f64::from(s);
            }
            if sw > 0.0 {
                dem[i] = (sh / sw) as f32;
                coh[i] = (sc / sw) as f32;
                sig[i] = (ss / sw) as f32;
            } else {
                labels[i] = label::LOW_COHERENCE;
            }
        }
    }
    // Accuracy in and out of the blend zones.
    let (mut ss_in, mut n_in, mut ss_out, mut n_out) = (0.0f64, 0usize, 0.0f64, 0usize);
    for (i, (&z, &t)) in dem.iter().zip(truth_grid.heights_m()).enumerate() {
        if !(z.is_finite() && t.is_finite()) {
            continue;
        }
        let d = f64::from(z) - f64::from(t);
        if blend_zone[i] {
            ss_in += d * d;
            n_in += 1;
        } else {
            ss_out += d * d;
            n_out += 1;
        }
    }
    let rms = |ss: f64, n: usize| {
        if n > 0 {
            (ss / n as f64).sqrt()
        } else {
            f64::NAN
        }
    };
    // The block nearest the map centre speaks for the map's geometry and processing figures.
    let centre = blocks
        .iter()
        .min_by_key(|b| {
            let c = b.record.block.core;
            let dr = (c.row0 + c.row1) as i64 - gh as i64;
            let dc = (c.col0 + c.col1) as i64 - gw as i64;
            dr * dr + dc * dc
        })
        .map(|b| &b.record)
        .ok_or_else(|| anyhow::anyhow!("no blocks"))?;
    let window = window_truth(job.truth, &truth_grid, centre.window_side_m)?;
    let mut sar = SarSummary {
        config: job.sar.clone(),
        derived: job.sar.derived()?,
        timings: Timings::default(),
        facets: [0; 3],
    };
    for b in &blocks {
        sar.timings += &b.record.sar_timings;
        for (a, v) in sar.facets.iter_mut().zip(b.record.facets) {
            *a += v;
        }
    }
    let mut unwrap = centre.unwrap;
    unwrap.pixels_changed = blocks.iter().map(|b| b.record.unwrap.pixels_changed).sum();
    unwrap.regions = blocks.iter().map(|b| b.record.unwrap.regions).sum();
    let report = MosaicReport {
        layout,
        overlap_cells_compared: compared,
        overlap_height_diff_rms_m: rms(diff_ss, compared),
        overlap_height_diff_max_m: diff_max,
        overlap_cycle_disagreements: cycles,
        cells_dropped_for_cycles: dropped,
        height_rmse_blend_zone_m: rms(ss_in, n_in),
        height_rmse_elsewhere_m: rms(ss_out, n_out),
        valid_cells: [n_in, n_out],
        per_block: blocks
            .iter()
            .map(|b| BlockLine {
                index: b.record.block.index,
                valid: b.record.mask.valid,
                unwrap_pixels_changed: b.record.unwrap.pixels_changed,
                datum_m: b.record.geometry.datum_m,
                sar_s: b.record.sar_timings.total_s,
                west_cycles_shifted: b.record.look_fusion.map(|f| f.west_cycles_shifted),
            })
            .collect(),
        peak_rss_mib: peak_rss_mib(),
    };
    let product = InsarProduct {
        geometry: centre.geometry,
        config: *job.cfg,
        grid: grid.clone(),
        dem: grid.raster(dem)?,
        coherence: grid.raster(coh)?,
        crlb_m: grid.raster(sig)?,
        mask: MaskFractions::of(&labels),
        labels,
        radar: RadarLayers {
            lines: 0,
            cols: 0,
            line_spacing_m: 0.0,
            phase_with_flat_rad: Vec::new(),
            phase_rad: Vec::new(),
            phase_unwrapped_rad: Vec::new(),
            coherence: Vec::new(),
            height_m: Vec::new(),
            ground_y_m: Vec::new(),
            labels: Vec::new(),
        },
        effective_looks: centre.effective_looks,
        crlb_filter_factor: centre.crlb_filter_factor,
        error_blur_m: centre.error_blur_m,
        coreg: centre.coreg,
        unwrap,
        eq20_removed: blocks.iter().map(|b| b.record.eq20_removed).sum(),
        geometry_removed: blocks.iter().map(|b| b.record.geometry_removed).sum(),
        coherence_mean_radar: blocks
            .iter()
            .map(|b| b.record.coherence_mean_radar)
            .sum::<f64>()
            / blocks.len() as f64,
        seconds: blocks.iter().map(|b| b.record.insar_s).sum(),
        look_fusion: fused_looks(&blocks),
        baseline_fusion: fused_baselines(&blocks),
    };
    Ok(Mosaic {
        truth: TruthOnGrid {
            grid: truth_grid,
            window,
            window_side_m: centre.window_side_m,
        },
        product,
        report,
        sar,
        filled_nodata: centre.filled_nodata,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cores_tile_the_grid_and_weights_sum_to_one() {
        for (w, h, b, o) in [
            (800, 800, 400, 25),
            (150, 97, 40, 8),
            (61, 200, 60, 0),
            (33, 33, 16, 8),
        ] {
            let l = BlockLayout::new(w, h, b, o).unwrap();
            let blocks = l.blocks();
            assert_eq!(blocks.len(), l.count());
            for row in 0..h {
                for col in 0..w {
                    let owners = blocks.iter().filter(|s| s.core.contains(row, col)).count();
                    assert_eq!(owners, 1, "cell ({row}, {col}) of {w}x{h}/{b}");
                    let sum: f64 = blocks.iter().map(|s| l.weight(s, row, col)).sum();
                    assert!(
                        (sum - 1.0).abs() < 1e-12,
                        "weights sum {sum} at ({row}, {col})"
                    );
                    for s in &blocks {
                        let wgt = l.weight(s, row, col);
                        assert!(wgt == 0.0 || s.extent.contains(row, col));
                    }
                }
            }
            for s in &blocks {
                assert!(s.core.width() <= b && s.core.height() <= b);
                assert!(s.extent.width() <= b + 2 * o && s.extent.height() <= b + 2 * o);
            }
        }
    }

    #[test]
    fn bad_layouts_are_refused() {
        assert!(BlockLayout::new(0, 10, 40, 8).is_err());
        assert!(BlockLayout::new(100, 100, 10, 8).is_err());
        let l = BlockLayout::new(100, 100, 40, 8).unwrap();
        assert_eq!(l.count(), 9);
        assert!(l.block(9).is_err());
    }
}
