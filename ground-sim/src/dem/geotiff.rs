//! Single-band GeoTIFF DEMs on top of the `tiff` crate.
//!
//! The container (IFDs, strips or tiles, LZW/Deflate/PackBits) is the crate's job; this file
//! interprets the GeoTIFF tags: ModelPixelScale (33550), ModelTiepoint (33922),
//! ModelTransformation (34264), the GeoKey directory and its parameter tags (34735–34737, kept
//! verbatim) and GDAL_NODATA (42113). Supported samples: float32, int16, uint16.

use std::fs::File;
use std::io::{BufReader, BufWriter, Cursor, Read, Seek, Write};
use std::path::Path;

use tiff::TiffError;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::colortype::{ColorType, Gray16, Gray32Float, GrayI16};
use tiff::encoder::compression::DeflateLevel;
use tiff::encoder::{Compression, TiffEncoder, TiffValue};
use tiff::tags::Tag;

use super::{Dem, DemError, GeoForm, GeoKeys, GeoRef, GeoTransform};

/// Sample type of a DEM file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
pub enum SampleKind {
    /// IEEE float32 metres.
    F32,
    /// Signed 16-bit integer metres (heights are rounded to the nearest metre on write).
    I16,
    /// Unsigned 16-bit integer metres (heights are rounded to the nearest metre on write).
    U16,
}

impl SampleKind {
    fn name(self) -> &'static str {
        match self {
            Self::F32 => "float32",
            Self::I16 => "int16",
            Self::U16 => "uint16",
        }
    }
}

const TAG_GDAL_NODATA: Tag = Tag::GdalNodata;

fn tiff_err(e: TiffError) -> DemError {
    match e {
        TiffError::UnsupportedError(u) => DemError::Unsupported(u.to_string()),
        TiffError::IoError(io) => DemError::Format(format!("I/O while decoding: {io}")),
        other => DemError::Format(other.to_string()),
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> DemError + '_ {
    move |source| DemError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Read a single-band GeoTIFF DEM from a file.
pub fn read_geotiff(path: &Path) -> Result<Dem, DemError> {
    let f = File::open(path).map_err(io_err(path))?;
    read_from(BufReader::new(f))
}

/// Read a single-band GeoTIFF DEM from memory.
pub fn read_geotiff_bytes(bytes: &[u8]) -> Result<Dem, DemError> {
    read_from(Cursor::new(bytes))
}

fn compression_name(code: u16) -> String {
    let name = match code {
        2 => "CCITT Huffman",
        3 | 4 => "CCITT fax",
        6 | 7 => "JPEG",
        34712 => "JPEG 2000",
        34887 => "LERC",
        34925 => "LZMA",
        50000 => "Zstandard",
        50001 => "WebP",
        _ => "unknown",
    };
    format!("compression {name} (code {code}); supported: none, LZW, Deflate, PackBits")
}

fn read_from<R: Read + Seek>(reader: R) -> Result<Dem, DemError> {
    let mut dec = Decoder::new(reader).map_err(tiff_err)?;
    let (w, h) = dec.dimensions().map_err(tiff_err)?;

    // Check the layout up front so the error names the reason, not a decoder detail.
    let tag_u16 = |dec: &mut Decoder<R>, tag: Tag| -> Result<Option<Vec<u16>>, DemError> {
        dec.find_tag_unsigned_vec::<u16>(tag).map_err(tiff_err)
    };
    let spp = tag_u16(&mut dec, Tag::SamplesPerPixel)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    if spp != 1 {
        return Err(DemError::Unsupported(format!(
            "{spp} bands (samples per pixel); only single-band DEMs are supported"
        )));
    }
    let compression = tag_u16(&mut dec, Tag::Compression)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    if !matches!(compression, 1 | 5 | 8 | 32946 | 32773) {
        return Err(DemError::Unsupported(compression_name(compression)));
    }
    let bits = tag_u16(&mut dec, Tag::BitsPerSample)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    let format = tag_u16(&mut dec, Tag::SampleFormat)?
        .and_then(|v| v.first().copied())
        .unwrap_or(1);
    let sample = match (format, bits) {
        (3, 32) => SampleKind::F32,
        (2, 16) => SampleKind::I16,
        (1, 16) => SampleKind::U16,
        (f, b) => {
            let kind = match f {
                1 => "uint",
                2 => "int",
                3 => "float",
                5 | 6 => "complex ",
                _ => "undefined-format ",
            };
            return Err(DemError::Unsupported(format!(
                "sample format {kind}{b}; supported: float32, int16, uint16"
            )));
        }
    };

    let geo = read_georef(&mut dec)?;
    let nodata = match dec
        .find_tag(TAG_GDAL_NODATA)
        .map_err(tiff_err)?
        .map(|v| v.into_string())
    {
        Some(Ok(s)) => Some(parse_nodata(&s)?),
        Some(Err(e)) => return Err(tiff_err(e)),
        None => None,
    };

    let data = dec.read_image().map_err(tiff_err)?;
    let n = (w as usize) * (h as usize);
    let nd = nodata.unwrap_or(f64::NAN);
    let mask = |v: f64| -> bool { nodata.is_some() && (v == nd || (nd.is_nan() && v.is_nan())) };
    let heights: Vec<f32> = match data {
        DecodingResult::F32(v) => v
            .into_iter()
            .map(|x| if mask(f64::from(x)) { f32::NAN } else { x })
            .collect(),
        DecodingResult::I16(v) => v
            .into_iter()
            .map(|x| {
                if mask(f64::from(x)) {
                    f32::NAN
                } else {
                    f32::from(x)
                }
            })
            .collect(),
        DecodingResult::U16(v) => v
            .into_iter()
            .map(|x| {
                if mask(f64::from(x)) {
                    f32::NAN
                } else {
                    f32::from(x)
                }
            })
            .collect(),
        _ => {
            return Err(DemError::Unsupported(format!(
                "decoded samples are not {}",
                sample.name()
            )));
        }
    };
    if heights.len() < n {
        return Err(DemError::Format(format!(
            "image holds {} samples, {w}x{h} needs {n}",
            heights.len()
        )));
    }
    let mut heights = heights;
    heights.truncate(n);
    let mut dem = Dem::new(w as usize, h as usize, heights, geo)?;
    dem.nodata = nodata;
    dem.sample = sample;
    Ok(dem)
}

fn parse_nodata(s: &str) -> Result<f64, DemError> {
    let t = s.trim().trim_matches(char::from(0));
    match t.to_ascii_lowercase().as_str() {
        "nan" | "-nan" => Ok(f64::NAN),
        _ => t
            .parse::<f64>()
            .map_err(|_| DemError::Format(format!("GDAL_NODATA value {t:?} is not a number"))),
    }
}

fn read_georef<R: Read + Seek>(dec: &mut Decoder<R>) -> Result<GeoRef, DemError> {
    let f64s = |dec: &mut Decoder<R>, tag: Tag| -> Result<Option<Vec<f64>>, DemError> {
        match dec.find_tag(tag).map_err(tiff_err)? {
            Some(v) => v.into_f64_vec().map(Some).map_err(tiff_err),
            None => Ok(None),
        }
    };
    let scale = f64s(dec, Tag::ModelPixelScaleTag)?;
    let tie = f64s(dec, Tag::ModelTiepointTag)?;
    let matrix = f64s(dec, Tag::ModelTransformationTag)?;
    let keys = match dec.find_tag(Tag::GeoKeyDirectoryTag).map_err(tiff_err)? {
        Some(v) => Some(GeoKeys {
            directory: v.into_u16_vec().map_err(tiff_err)?,
            doubles: f64s(dec, Tag::GeoDoubleParamsTag)?,
            ascii: match dec.find_tag(Tag::GeoAsciiParamsTag).map_err(tiff_err)? {
                Some(v) => Some(v.into_string().map_err(tiff_err)?),
                None => None,
            },
        }),
        None => None,
    };
    // PixelIsPoint tie points name pixel centres; our transform names corners (GDAL's choice).
    let half = if keys.as_ref().is_some_and(GeoKeys::pixel_is_point) {
        0.5
    } else {
        0.0
    };

    let (transform, form) = match (scale, tie, matrix) {
        (_, _, Some(m)) => {
            let m: [f64; 16] = m.try_into().map_err(|v: Vec<f64>| {
                DemError::Format(format!(
                    "ModelTransformation has {} values, not 16",
                    v.len()
                ))
            })?;
            let t = [
                m[3] - half * (m[0] + m[1]),
                m[0],
                m[1],
                m[7] - half * (m[4] + m[5]),
                m[4],
                m[5],
            ];
            (GeoTransform(t), GeoForm::Matrix { m })
        }
        (Some(s), Some(t), None) => {
            if s.len() < 2 || t.len() < 6 {
                return Err(DemError::Format(
                    "ModelPixelScale needs 3 values and ModelTiepoint 6".into(),
                ));
            }
            if t.len() > 6 {
                return Err(DemError::Unsupported(format!(
                    "{} tie points without a single transform (ground control points)",
                    t.len() / 6
                )));
            }
            let (sx, sy) = (s[0], s[1]);
            let x0 = t[3] - (t[0] + half) * sx;
            let y0 = t[4] + (t[1] + half) * sy;
            let form = GeoForm::ScaleTiepoint {
                z_scale: s.get(2).copied().unwrap_or(0.0),
                tie_z: t[5],
            };
            (GeoTransform([x0, sx, 0.0, y0, 0.0, -sy]), form)
        }
        _ => {
            return Err(DemError::Unsupported(
                "no georeferencing (needs ModelPixelScale + ModelTiepoint or ModelTransformation)"
                    .into(),
            ));
        }
    };
    Ok(GeoRef {
        transform,
        keys,
        form,
    })
}

/// Write `dem` as a single-band, Deflate-compressed GeoTIFF. `kind` overrides the sample type
/// (default: the DEM's own). Integer types round heights to the nearest metre; heights out of the
/// type's range, or `NaN`s without a representable nodata value, are errors.
pub fn write_geotiff(dem: &Dem, path: &Path, kind: Option<SampleKind>) -> Result<(), DemError> {
    let f = File::create(path).map_err(io_err(path))?;
    let mut w = BufWriter::new(f);
    write_to(dem, &mut w, kind)?;
    w.flush().map_err(io_err(path))
}

/// Write `dem` as GeoTIFF bytes (see [`write_geotiff`]).
pub fn write_geotiff_bytes(dem: &Dem, kind: Option<SampleKind>) -> Result<Vec<u8>, DemError> {
    let mut c = Cursor::new(Vec::new());
    write_to(dem, &mut c, kind)?;
    Ok(c.into_inner())
}

fn write_to<W: Write + Seek>(
    dem: &Dem,
    w: &mut W,
    kind: Option<SampleKind>,
) -> Result<(), DemError> {
    let kind = kind.unwrap_or(dem.sample);
    let width = u32::try_from(dem.width()).map_err(|_| DemError::Invalid("width".into()))?;
    let height = u32::try_from(dem.height()).map_err(|_| DemError::Invalid("height".into()))?;
    let has_nan = dem.heights_m().iter().any(|h| !h.is_finite());
    match kind {
        SampleKind::F32 => {
            // NaN stays NaN unless the file has a finite nodata value.
            let nd = dem.nodata.filter(|v| !v.is_nan()).map(|v| v as f32);
            let data: Vec<f32> = match nd {
                Some(v) => dem
                    .heights_m()
                    .iter()
                    .map(|&h| if h.is_finite() { h } else { v })
                    .collect(),
                None => dem.heights_m().to_vec(),
            };
            let nodata_text = match (dem.nodata, has_nan) {
                (Some(v), _) if !v.is_nan() => Some(format_nodata(v)),
                (Some(_), _) | (None, true) => Some("nan".to_string()),
                (None, false) => None,
            };
            encode::<_, Gray32Float>(w, width, height, &data, dem, nodata_text.as_deref())
        }
        SampleKind::I16 => {
            let (data, nd) = to_int(dem, i16::MIN.into(), i16::MAX.into(), has_nan, kind)?;
            let data: Vec<i16> = data.into_iter().map(|v| v as i16).collect();
            encode::<_, GrayI16>(w, width, height, &data, dem, nd.as_deref())
        }
        SampleKind::U16 => {
            let (data, nd) = to_int(dem, 0.0, u16::MAX.into(), has_nan, kind)?;
            let data: Vec<u16> = data.into_iter().map(|v| v as u16).collect();
            encode::<_, Gray16>(w, width, height, &data, dem, nd.as_deref())
        }
    }
}

fn format_nodata(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v}")
    }
}

/// Heights rounded for an integer type, with NaN replaced by the nodata value.
fn to_int(
    dem: &Dem,
    lo: f64,
    hi: f64,
    has_nan: bool,
    kind: SampleKind,
) -> Result<(Vec<f64>, Option<String>), DemError> {
    let nd = dem.nodata.filter(|v| v.is_finite());
    if has_nan && nd.is_none() {
        return Err(DemError::Invalid(format!(
            "DEM has nodata samples but no integer nodata value to write them as {}",
            kind.name()
        )));
    }
    if let Some(v) = nd
        && (v < lo || v > hi || v.fract() != 0.0)
    {
        return Err(DemError::Invalid(format!(
            "nodata value {v} does not fit {}",
            kind.name()
        )));
    }
    let mut out = Vec::with_capacity(dem.heights_m().len());
    for &h in dem.heights_m() {
        let v = if h.is_finite() {
            let r = f64::from(h).round();
            if r < lo || r > hi {
                return Err(DemError::Invalid(format!(
                    "height {h} m does not fit {}",
                    kind.name()
                )));
            }
            r
        } else {
            nd.unwrap_or(0.0)
        };
        out.push(v);
    }
    Ok((out, nd.map(format_nodata)))
}

fn encode<W, C>(
    w: &mut W,
    width: u32,
    height: u32,
    data: &[C::Inner],
    dem: &Dem,
    nodata: Option<&str>,
) -> Result<(), DemError>
where
    W: Write + Seek,
    C: ColorType,
    [C::Inner]: TiffValue,
{
    let mut enc = TiffEncoder::new(w)
        .map_err(tiff_err)?
        .with_compression(Compression::Deflate(DeflateLevel::Balanced));
    let mut img = enc.new_image::<C>(width, height).map_err(tiff_err)?;
    let e = img.encoder();
    let geo = &dem.geo;
    let half = if geo.keys.as_ref().is_some_and(GeoKeys::pixel_is_point) {
        0.5
    } else {
        0.0
    };
    let t = geo.transform.0;
    match geo.form {
        GeoForm::ScaleTiepoint { z_scale, tie_z } if geo.transform.is_north_up() => {
            let (sx, sy) = (t[1], -t[5]);
            let tie = [0.0, 0.0, 0.0, t[0] + half * sx, t[3] - half * sy, tie_z];
            e.write_tag(Tag::ModelPixelScaleTag, &[sx, sy, z_scale][..])
                .map_err(tiff_err)?;
            e.write_tag(Tag::ModelTiepointTag, &tie[..])
                .map_err(tiff_err)?;
        }
        form => {
            let mut m = match form {
                GeoForm::Matrix { m } => m,
                GeoForm::ScaleTiepoint { .. } => {
                    let mut m = [0.0; 16];
                    m[10] = 1.0;
                    m[15] = 1.0;
                    m
                }
            };
            m[0] = t[1];
            m[1] = t[2];
            m[3] = t[0] + half * (t[1] + t[2]);
            m[4] = t[4];
            m[5] = t[5];
            m[7] = t[3] + half * (t[4] + t[5]);
            e.write_tag(Tag::ModelTransformationTag, &m[..])
                .map_err(tiff_err)?;
        }
    }
    if let Some(k) = &geo.keys {
        e.write_tag(Tag::GeoKeyDirectoryTag, &k.directory[..])
            .map_err(tiff_err)?;
        if let Some(d) = &k.doubles {
            e.write_tag(Tag::GeoDoubleParamsTag, &d[..])
                .map_err(tiff_err)?;
        }
        if let Some(a) = &k.ascii {
            e.write_tag(Tag::GeoAsciiParamsTag, a.as_str())
                .map_err(tiff_err)?;
        }
    }
    if let Some(nd) = nodata {
        e.write_tag(TAG_GDAL_NODATA, nd).map_err(tiff_err)?;
    }
    img.write_data(data).map_err(tiff_err)
}
