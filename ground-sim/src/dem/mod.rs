//! Digital elevation models: a georeferenced grid of heights in metres.
//!
//! Conventions (the same as nav-core's frames): row-major storage, `col` grows to the right
//! (east, map `+x`), `row` grows downwards (map `-y` for north-up grids), and the centre of pixel
//! `(col, row)` sits at image coordinates `(col, row)`. The geotransform below is GDAL's: it maps
//! pixel *corner* coordinates, so the first pixel's centre is at `(x0 + dx/2, y0 + dy/2)` (with
//! `dy < 0` for north-up grids).
//!
//! Missing heights are `NaN` inside a [`Dem`], whatever the nodata value of the file was.

mod geotiff;
mod resample;
pub mod spectrum;
pub mod stats;

pub use geotiff::{
    SampleKind, read_geotiff, read_geotiff_bytes, write_geotiff, write_geotiff_bytes,
};
pub use resample::{Interpolation, resample_to_pixel};

use thiserror::Error;

/// Why a DEM could not be read, written or transformed.
#[derive(Debug, Error)]
pub enum DemError {
    /// File system error, with the path involved.
    #[error("{path}: {source}")]
    Io {
        /// File that failed.
        path: String,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The TIFF container is malformed.
    #[error("malformed TIFF: {0}")]
    Format(String),
    /// A valid TIFF whose layout this reader does not handle; the text names what is unsupported.
    #[error("unsupported GeoTIFF layout: {0}")]
    Unsupported(String),
    /// Values or parameters that cannot be represented (out of range heights, bad pixel size…).
    #[error("invalid DEM: {0}")]
    Invalid(String),
}

/// GDAL-style affine geotransform of the pixel *corner* grid, in map units (metres for every
/// projected CRS Umbra uses).
///
/// `x = c[0] + col·c[1] + row·c[2]`, `y = c[3] + col·c[4] + row·c[5]`, where `(col, row) = (0, 0)`
/// is the outer corner of the first pixel. North-up grids have `c[2] = c[4] = 0` and `c[5] < 0`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GeoTransform(pub [f64; 6]);

impl GeoTransform {
    /// A north-up grid whose first pixel has its upper-left corner at `(x0_m, y0_m)`, with square
    /// pixels of `pixel_m` metres.
    pub fn north_up(x0_m: f64, y0_m: f64, pixel_m: f64) -> Self {
        Self([x0_m, pixel_m, 0.0, y0_m, 0.0, -pixel_m])
    }

    /// Map coordinates (metres) of pixel-corner coordinates `(col, row)`.
    pub fn apply(&self, col: f64, row: f64) -> (f64, f64) {
        let c = &self.0;
        (
            c[0] + col * c[1] + row * c[2],
            c[3] + col * c[4] + row * c[5],
        )
    }

    /// Whether the grid is north-up (no rotation or shear terms).
    pub fn is_north_up(&self) -> bool {
        self.0[2] == 0.0 && self.0[4] == 0.0
    }

    /// Square pixel size in metres, or an error for rotated, sheared or non-square grids
    /// (nav-core's slope needs one ground sample distance).
    pub fn square_pixel_m(&self) -> Result<f64, DemError> {
        let (dx, dy) = (self.0[1], -self.0[5]);
        let square = dx > 0.0 && dx.is_finite() && ((dy - dx) / dx).abs() < 1e-9;
        if self.is_north_up() && square {
            Ok(dx)
        } else {
            Err(DemError::Unsupported(format!(
                "grid must be north-up with square pixels, geotransform is {:?}",
                self.0
            )))
        }
    }
}

/// Georeferencing tags kept verbatim from the input so that a DEM written back carries the same
/// coordinate reference system (GeoKeyDirectory, GeoDoubleParams, GeoAsciiParams).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GeoKeys {
    /// GeoKeyDirectoryTag (34735) SHORT values, as read.
    pub directory: Vec<u16>,
    /// GeoDoubleParamsTag (34736), as read.
    pub doubles: Option<Vec<f64>>,
    /// GeoAsciiParamsTag (34737), as read (without the trailing NUL).
    pub ascii: Option<String>,
}

/// GeoKey id of GTRasterTypeGeoKey.
const GT_RASTER_TYPE_KEY: u16 = 1025;
/// GTRasterTypeGeoKey value RasterPixelIsPoint (tie point names a pixel centre).
const RASTER_PIXEL_IS_POINT: u16 = 2;

impl GeoKeys {
    /// Keys for Umbra's synthetic scenes: a projected, user-defined local metric grid.
    pub fn local_metric_grid(citation: &str) -> Self {
        let ascii = format!("{citation}|");
        let n = u16::try_from(ascii.len()).unwrap_or(u16::MAX);
        Self {
            // Header (version 1, revision 1.0, 4 keys), then (id, location, count, value) quads:
            // GTModelType = projected (1), GTRasterType = PixelIsArea (1),
            // GTCitation in the ASCII params, ProjLinearUnits = metre (9001).
            directory: vec![
                1, 1, 0, 4, //
                1024, 0, 1, 1, //
                1025, 0, 1, 1, //
                1026, 34737, n, 0, //
                3076, 0, 1, 9001,
            ],
            doubles: None,
            ascii: Some(ascii),
        }
    }

    /// The value of a SHORT GeoKey stored inline in the directory.
    pub fn short_key(&self, key: u16) -> Option<u16> {
        let n = usize::from(*self.directory.get(3)?);
        (0..n).find_map(|i| {
            let q = self.directory.get(4 + 4 * i..8 + 4 * i)?;
            (q[0] == key && q[1] == 0).then_some(q[3])
        })
    }

    /// Whether GTRasterTypeGeoKey says RasterPixelIsPoint.
    pub fn pixel_is_point(&self) -> bool {
        self.short_key(GT_RASTER_TYPE_KEY) == Some(RASTER_PIXEL_IS_POINT)
    }
}

/// How the georeferencing was (and will be) stored in the TIFF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GeoForm {
    /// ModelPixelScale + ModelTiepoint; the Z scale and the tie point's Z are kept for output.
    ScaleTiepoint {
        /// Third value of ModelPixelScale.
        z_scale: f64,
        /// Z of the model tie point.
        tie_z: f64,
    },
    /// ModelTransformation 4×4 matrix (third row and column kept for output).
    Matrix {
        /// Row-major matrix as read; only the x/y affine terms are replaced on output.
        m: [f64; 16],
    },
}

/// Georeferencing of a DEM.
#[derive(Debug, Clone, PartialEq)]
pub struct GeoRef {
    /// Pixel-corner geotransform (see [`GeoTransform`]).
    pub transform: GeoTransform,
    /// GeoKeys kept from the input, if any.
    pub keys: Option<GeoKeys>,
    /// Storage form of the transform in the file.
    pub form: GeoForm,
}

impl GeoRef {
    /// A north-up local metric grid (used by synthetic terrain).
    pub fn local(x0_m: f64, y0_m: f64, pixel_m: f64, citation: &str) -> Self {
        Self {
            transform: GeoTransform::north_up(x0_m, y0_m, pixel_m),
            keys: Some(GeoKeys::local_metric_grid(citation)),
            form: GeoForm::ScaleTiepoint {
                z_scale: 0.0,
                tie_z: 0.0,
            },
        }
    }
}

/// A georeferenced DEM: `width × height` heights in metres, `NaN` where there is no data.
#[derive(Debug, Clone, PartialEq)]
pub struct Dem {
    width: usize,
    height: usize,
    heights_m: Vec<f32>,
    /// Georeferencing.
    pub geo: GeoRef,
    /// Nodata value of the source file (GDAL_NODATA), used again when writing. `NaN` for float
    /// files marked "nan".
    pub nodata: Option<f64>,
    /// Sample type of the source file (the default for writing it back).
    pub sample: SampleKind,
}

impl Dem {
    /// Build a DEM, checking that the buffer holds `width × height` heights.
    pub fn new(
        width: usize,
        height: usize,
        heights_m: Vec<f32>,
        geo: GeoRef,
    ) -> Result<Self, DemError> {
        if width == 0 || height == 0 {
            return Err(DemError::Invalid("zero width or height".into()));
        }
        let n = width
            .checked_mul(height)
            .ok_or_else(|| DemError::Invalid("width x height overflows".into()))?;
        if n != heights_m.len() {
            return Err(DemError::Invalid(format!(
                "{width}x{height} grid needs {n} heights, got {}",
                heights_m.len()
            )));
        }
        Ok(Self {
            width,
            height,
            heights_m,
            geo,
            nodata: None,
            sample: SampleKind::F32,
        })
    }

    /// Width in pixels (columns).
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels (rows).
    pub fn height(&self) -> usize {
        self.height
    }
    /// Heights in metres, row-major, `NaN` = no data.
    pub fn heights_m(&self) -> &[f32] {
        &self.heights_m
    }
    /// Mutable heights in metres.
    pub fn heights_m_mut(&mut self) -> &mut [f32] {
        &mut self.heights_m
    }
    /// Take the height buffer.
    pub fn into_heights(self) -> Vec<f32> {
        self.heights_m
    }

    /// Height at integer pixel `(col, row)`, `None` outside or where no data.
    pub fn get(&self, col: usize, row: usize) -> Option<f32> {
        if col >= self.width || row >= self.height {
            return None;
        }
        self.heights_m
            .get(row * self.width + col)
            .copied()
            .filter(|h| h.is_finite())
    }

    /// Square pixel size in metres (error for rotated or non-square grids).
    pub fn pixel_m(&self) -> Result<f64, DemError> {
        self.geo.transform.square_pixel_m()
    }

    /// Map coordinates (metres) of the upper-left corner of the grid.
    pub fn origin_m(&self) -> (f64, f64) {
        self.geo.transform.apply(0.0, 0.0)
    }

    /// Map coordinates (metres) of the centre of pixel `(col, row)` (pixel-centre convention).
    pub fn pixel_centre_m(&self, col: f64, row: f64) -> (f64, f64) {
        self.geo.transform.apply(col + 0.5, row + 0.5)
    }

    /// Map extent `(x_min, y_min, x_max, y_max)` in metres of the outer pixel corners.
    pub fn extent_m(&self) -> (f64, f64, f64, f64) {
        let (w, h) = (self.width as f64, self.height as f64);
        let corners =
            [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)].map(|(c, r)| self.geo.transform.apply(c, r));
        let xs = corners.map(|p| p.0);
        let ys = corners.map(|p| p.1);
        let fold_min = |a: [f64; 4]| a.into_iter().fold(f64::INFINITY, f64::min);
        let fold_max = |a: [f64; 4]| a.into_iter().fold(f64::NEG_INFINITY, f64::max);
        (fold_min(xs), fold_min(ys), fold_max(xs), fold_max(ys))
    }

    /// Number of nodata (`NaN`) samples.
    pub fn nodata_count(&self) -> usize {
        self.heights_m.iter().filter(|h| !h.is_finite()).count()
    }

    /// Crop to the pixels whose centres lie inside the map rectangle `[x_min, x_max] × [y_min,
    /// y_max]` (metres). The result keeps the CRS and pixel size; its corner moves to the first
    /// kept pixel. Errors if the rectangle holds no pixel centre or the grid is rotated.
    pub fn crop_geo(
        &self,
        x_min: f64,
        y_min: f64,
        x_max: f64,
        y_max: f64,
    ) -> Result<Dem, DemError> {
        let t = &self.geo.transform;
        if !t.is_north_up() {
            return Err(DemError::Unsupported("cropping a rotated grid".into()));
        }
        if !(x_min < x_max && y_min < y_max) {
            return Err(DemError::Invalid(format!(
                "crop rectangle x {x_min}..{x_max}, y {y_min}..{y_max} is empty"
            )));
        }
        let c = &t.0;
        // Pixel-centre index k has map coordinate c0 + (k + 0.5)·d; solve for the range of k.
        let range = |lo: f64, hi: f64, c0: f64, d: f64, n: usize| -> Option<(usize, usize)> {
            let (a, b) = ((lo - c0) / d - 0.5, (hi - c0) / d - 0.5);
            let (a, b) = (a.min(b), a.max(b));
            let first = a.ceil().max(0.0);
            let last = b.floor().min(n as f64 - 1.0);
            (first <= last).then_some((first as usize, last as usize))
        };
        let cols = range(x_min, x_max, c[0], c[1], self.width);
        let rows = range(y_min, y_max, c[3], c[5], self.height);
        let (Some((c0, c1)), Some((r0, r1))) = (cols, rows) else {
            return Err(DemError::Invalid(format!(
                "crop rectangle x {x_min}..{x_max}, y {y_min}..{y_max} misses the DEM extent {:?}",
                self.extent_m()
            )));
        };
        self.crop_px(c0, r0, c1 - c0 + 1, r1 - r0 + 1)
    }

    /// Crop to `w × h` pixels starting at pixel `(col0, row0)`.
    pub fn crop_px(&self, col0: usize, row0: usize, w: usize, h: usize) -> Result<Dem, DemError> {
        if w == 0 || h == 0 || col0 + w > self.width || row0 + h > self.height {
            return Err(DemError::Invalid(format!(
                "crop {w}x{h} at ({col0}, {row0}) exceeds the {}x{} grid",
                self.width, self.height
            )));
        }
        let mut out = Vec::with_capacity(w * h);
        for r in row0..row0 + h {
            let start = r * self.width + col0;
            out.extend_from_slice(self.heights_m.get(start..start + w).unwrap_or(&[]));
        }
        let mut geo = self.geo.clone();
        let (x0, y0) = self.geo.transform.apply(col0 as f64, row0 as f64);
        geo.transform.0[0] = x0;
        geo.transform.0[3] = y0;
        let mut dem = Dem::new(w, h, out, geo)?;
        dem.nodata = self.nodata;
        dem.sample = self.sample;
        Ok(dem)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> Dem {
        let z = (0..w * h).map(|i| i as f32).collect();
        Dem::new(w, h, z, GeoRef::local(1000.0, 2000.0, 5.0, "test")).unwrap()
    }

    #[test]
    fn geo_crop_picks_pixel_centres_inside() {
        let d = ramp(10, 8);
        // Pixel centres: x = 1002.5 + 5·col, y = 1997.5 − 5·row.
        let c = d.crop_geo(1010.0, 1980.0, 1025.0, 1995.0).unwrap();
        assert_eq!((c.width(), c.height()), (3, 3));
        // First kept centre: col 2 (1012.5), row 1 (1992.5).
        assert_eq!(c.get(0, 0), Some((10 + 2) as f32));
        assert_eq!(c.origin_m(), (1010.0, 1995.0));
        assert_eq!(c.pixel_centre_m(0.0, 0.0), d.pixel_centre_m(2.0, 1.0));
        assert!(d.crop_geo(0.0, 0.0, 10.0, 10.0).is_err());
        assert!(d.crop_geo(1010.0, 1990.0, 1005.0, 1995.0).is_err());
    }

    #[test]
    fn local_keys_are_parsed() {
        let k = GeoKeys::local_metric_grid("x");
        assert_eq!(k.short_key(1024), Some(1));
        assert!(!k.pixel_is_point());
    }
}
