//! Output products of a `sar` run: SLC files, σ0 PNGs (the paper's Fig. 4c, f) and the JSON
//! report.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::config::{Derived, SarConfig};
use super::geometry::AcquisitionPlan;
use super::pipeline::{InsarPair, Timings};
use super::scene::SceneStats;
use super::slc::Slc;
use super::{SarError, SarResult};

/// σ0 shown black in the PNG, dB.
pub const PNG_DB_MIN: f64 = -30.0;
/// σ0 shown white in the PNG, dB.
pub const PNG_DB_MAX: f64 = 10.0;

/// Description of one written SLC.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlcProduct {
    /// File name inside the output directory.
    pub file: String,
    /// σ0 PNG file name.
    pub sigma0_png: String,
    /// Antenna number (1 or 2).
    pub antenna: u8,
    /// Channel (`HH` or `VV`).
    pub polarisation: String,
    /// Azimuth lines.
    pub lines: usize,
    /// Range gates.
    pub gates: usize,
    /// Slant range of gate 0, m.
    pub first_range_m: f64,
    /// Gate spacing, m.
    pub range_spacing_m: f64,
    /// Along-track position of line 0, m.
    pub first_azimuth_m: f64,
    /// Line spacing, m.
    pub azimuth_spacing_m: f64,
    /// Antenna track `(y, z)`, m.
    pub antenna_yz_m: [f64; 2],
    /// Resolution area A0 (eq 16) at the first gate, m².
    pub resolution_area_first_gate_m2: f64,
    /// Mean σ0 over the image, dB.
    pub mean_sigma0_db: f64,
}

/// The JSON report of a `sar` run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SarReport {
    /// Configuration used.
    pub config: SarConfig,
    /// Derived radar values.
    pub derived: Derived,
    /// Geometry, pulse grid, echo window, SLC crop.
    pub plan: AcquisitionPlan,
    /// DEM as given: nodes and spacing.
    pub dem_nodes: [usize; 2],
    /// DEM spacing, m.
    pub dem_pixel_m: f64,
    /// Facet statistics.
    pub scene: SceneStats,
    /// Scatterers simulated.
    pub scatterers: usize,
    /// Raw noise power per sample (None: noise off).
    pub raw_noise_power: Option<f64>,
    /// SLC products.
    pub slcs: Vec<SlcProduct>,
    /// Stage timings, s.
    pub timings: Timings,
    /// Time to write the products, s.
    pub write_s: f64,
    /// Peak resident memory of the process (Linux VmHWM), MiB, if known.
    pub peak_memory_mib: Option<f64>,
    /// PNG grey scale: σ0 in dB mapped linearly from `[min, max]` to `[0, 255]`.
    pub png_db_range: [f64; 2],
}

/// Peak resident set size from `/proc/self/status` (VmHWM), MiB.
pub fn peak_memory_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Write the σ0 image of `slc` as an 8-bit grey PNG (rows = azimuth, columns = range, near
/// range on the left: the radar looks from the left as in the paper's Fig. 4).
pub fn write_sigma0_png(slc: &Slc, path: &Path) -> SarResult<f64> {
    let s0 = slc.sigma0();
    let mean = s0.iter().map(|&v| f64::from(v)).sum::<f64>() / s0.len().max(1) as f64;
    let px: Vec<u8> = s0
        .iter()
        .map(|&v| {
            let db = 10.0 * f64::from(v).max(1e-30).log10();
            let t = ((db - PNG_DB_MIN) / (PNG_DB_MAX - PNG_DB_MIN)).clamp(0.0, 1.0);
            (t * 255.0).round() as u8
        })
        .collect();
    let w = u32::try_from(slc.gates).map_err(|_| SarError::Format("image too wide".into()))?;
    let h = u32::try_from(slc.lines).map_err(|_| SarError::Format("image too tall".into()))?;
    let img = image::GrayImage::from_raw(w, h, px)
        .ok_or_else(|| SarError::Shape("σ0 buffer size".into()))?;
    img.save(path)
        .map_err(|e| SarError::Io(std::io::Error::other(e.to_string())))?;
    Ok(10.0 * mean.max(1e-30).log10())
}

/// Write every SLC (`slc_a{1,2}_{hh,vv}.bin`), its σ0 PNG and `report.json` into `dir`.
pub fn write_products(
    pair: &InsarPair,
    dem_nodes: [usize; 2],
    dem_pixel_m: f64,
    dir: &Path,
) -> SarResult<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let t = std::time::Instant::now();
    let mut products = Vec::new();
    for slc in &pair.slcs {
        let stem = format!("slc_a{}_{}", slc.antenna.number(), slc.polarisation.tag());
        let file = format!("{stem}.bin");
        slc.write_to(BufWriter::new(File::create(dir.join(&file))?))?;
        let png = format!(
            "sigma0_a{}_{}.png",
            slc.antenna.number(),
            slc.polarisation.tag()
        );
        let mean_db = write_sigma0_png(slc, &dir.join(&png))?;
        products.push(SlcProduct {
            file,
            sigma0_png: png,
            antenna: slc.antenna.number(),
            polarisation: format!("{:?}", slc.polarisation),
            lines: slc.lines,
            gates: slc.gates,
            first_range_m: slc.first_range_m,
            range_spacing_m: slc.range_spacing_m,
            first_azimuth_m: slc.first_azimuth_m,
            azimuth_spacing_m: slc.azimuth_spacing_m,
            antenna_yz_m: slc.antenna_yz_m,
            resolution_area_first_gate_m2: slc.resolution_area_m2(0.0),
            mean_sigma0_db: mean_db,
        });
    }
    let report = SarReport {
        config: pair.config.clone(),
        derived: pair.derived.clone(),
        plan: pair.plan.clone(),
        dem_nodes,
        dem_pixel_m,
        scene: pair.stats,
        scatterers: pair.scatterers,
        raw_noise_power: pair.raw_noise_power,
        slcs: products,
        timings: pair.timings.clone(),
        write_s: t.elapsed().as_secs_f64(),
        peak_memory_mib: peak_memory_mib(),
        png_db_range: [PNG_DB_MIN, PNG_DB_MAX],
    };
    let path = dir.join("report.json");
    let text =
        serde_json::to_string_pretty(&report).map_err(|e| SarError::Format(e.to_string()))?;
    std::fs::write(&path, text)?;
    Ok(path)
}
