//! Single-look complex image with its geometry, eq 16 σ0, and the `UMBRASLC` file format
//! (spec and byte table in `docs/sar.md`).

use std::io::{Read, Write};

use super::config::Polarisation;
use super::geometry::Antenna;
use super::{C32, SarError, SarResult};

/// File magic of SLC files.
pub const SLC_MAGIC: [u8; 8] = *b"UMBRASLC";
/// Format version written and accepted.
pub const SLC_VERSION: u16 = 1;
/// Header length, bytes.
pub const SLC_HEADER_LEN: usize = 128;
/// Largest image accepted when reading (lines × gates).
pub const SLC_MAX_SAMPLES: usize = 1 << 28;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// A focused single-look complex image of one antenna and channel.
///
/// Pixel `(line i, gate j)` is the target at along-track `x = first_azimuth_m + i·azimuth_spacing_m`
/// and closest-approach slant range `first_range_m + j·range_spacing_m` from this antenna's
/// track; its phase is `−4πR/λ` plus the scattering phase. A point scatterer of amplitude `S`
/// focuses to a peak of `|S|`.
#[derive(Debug, Clone, PartialEq)]
pub struct Slc {
    /// Antenna that transmitted and received.
    pub antenna: Antenna,
    /// Channel.
    pub polarisation: Polarisation,
    /// Azimuth lines (rows).
    pub lines: usize,
    /// Range gates (columns).
    pub gates: usize,
    /// Row-major samples, `lines × gates`.
    pub data: Vec<C32>,
    /// Slant range of gate 0, m.
    pub first_range_m: f64,
    /// Slant-range gate spacing, m.
    pub range_spacing_m: f64,
    /// Along-track position of line 0, m.
    pub first_azimuth_m: f64,
    /// Line spacing, m.
    pub azimuth_spacing_m: f64,
    /// Wavelength, m.
    pub wavelength_m: f64,
    /// `(y, z)` of this antenna's track in the local frame, m.
    pub antenna_yz_m: [f64; 2],
    /// Platform speed, m/s.
    pub velocity_m_s: f64,
    /// `∫|h_r|² dr` of the unit-peak range response, slant m.
    pub range_energy_width_m: f64,
    /// `∫|h_a|² dx` of the unit-peak azimuth response, m.
    pub azimuth_energy_width_m: f64,
    /// Height of the flat datum used for the incidence in eq 16, m.
    pub reference_height_m: f64,
}

impl Slc {
    /// Sample at (`line`, `gate`), `None` outside the image.
    pub fn get(&self, line: usize, gate: usize) -> Option<C32> {
        (line < self.lines && gate < self.gates).then(|| self.data[line * self.gates + gate])
    }
    /// Slant range of gate `j`, m.
    pub fn range_of_gate(&self, j: f64) -> f64 {
        self.first_range_m + j * self.range_spacing_m
    }
    /// Along-track position of line `i`, m.
    pub fn azimuth_of_line(&self, i: f64) -> f64 {
        self.first_azimuth_m + i * self.azimuth_spacing_m
    }
    /// Antenna phase centre when imaging line `i` (zero Doppler), local frame, m.
    pub fn antenna_position(&self, i: f64) -> [f64; 3] {
        [
            self.azimuth_of_line(i),
            self.antenna_yz_m[0],
            self.antenna_yz_m[1],
        ]
    }
    /// Incidence on the flat datum at gate `j`, rad.
    pub fn flat_incidence_rad(&self, j: f64) -> f64 {
        let h = self.antenna_yz_m[1] - self.reference_height_m;
        (h / self.range_of_gate(j)).clamp(-1.0, 1.0).acos()
    }
    /// Ground resolution area A0 of eq 16 at gate `j`: `∫|h|² dA` of the unit-peak PSF on the
    /// flat datum, m².
    pub fn resolution_area_m2(&self, j: f64) -> f64 {
        self.range_energy_width_m / self.flat_incidence_rad(j).sin() * self.azimuth_energy_width_m
    }

    /// σ0 image (eq 16): `4π|I|²/A0`, linear, `lines × gates`.
    pub fn sigma0(&self) -> Vec<f32> {
        let k: Vec<f64> = (0..self.gates)
            .map(|j| 4.0 * std::f64::consts::PI / self.resolution_area_m2(j as f64))
            .collect();
        self.data
            .iter()
            .enumerate()
            .map(|(i, v)| (f64::from(v.norm_sqr()) * k[i % self.gates]) as f32)
            .collect()
    }

    /// Serialise: 128-byte little-endian header then `lines × gates` pairs of f32 (re, im).
    pub fn write_to<W: Write>(&self, mut w: W) -> SarResult<()> {
        let mut payload = Vec::with_capacity(self.data.len() * 8);
        for v in &self.data {
            payload.extend_from_slice(&v.re.to_le_bytes());
            payload.extend_from_slice(&v.im.to_le_bytes());
        }
        let lines =
            u32::try_from(self.lines).map_err(|_| SarError::Format("too many lines".into()))?;
        let gates =
            u32::try_from(self.gates).map_err(|_| SarError::Format("too many gates".into()))?;
        let mut h = Vec::with_capacity(SLC_HEADER_LEN);
        h.extend_from_slice(&SLC_MAGIC);
        h.extend_from_slice(&SLC_VERSION.to_le_bytes());
        h.push(self.antenna.number());
        h.push(self.polarisation.code());
        h.extend_from_slice(&lines.to_le_bytes());
        h.extend_from_slice(&gates.to_le_bytes());
        h.extend_from_slice(&CRC32.checksum(&payload).to_le_bytes());
        for v in [
            self.first_range_m,
            self.range_spacing_m,
            self.first_azimuth_m,
            self.azimuth_spacing_m,
            self.wavelength_m,
            self.antenna_yz_m[0],
            self.antenna_yz_m[1],
            self.velocity_m_s,
            self.range_energy_width_m,
            self.azimuth_energy_width_m,
            self.reference_height_m,
        ] {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h.resize(SLC_HEADER_LEN, 0);
        w.write_all(&h)?;
        w.write_all(&payload)?;
        Ok(())
    }

    /// Parse and validate (magic, version, sizes, checksum) a file written by [`Slc::write_to`].
    pub fn read_from<R: Read>(mut r: R) -> SarResult<Self> {
        let mut h = [0u8; SLC_HEADER_LEN];
        r.read_exact(&mut h)?;
        if h[0..8] != SLC_MAGIC {
            return Err(SarError::Format("bad magic".into()));
        }
        let u16_at = |o: usize| u16::from_le_bytes([h[o], h[o + 1]]);
        let u32_at = |o: usize| u32::from_le_bytes([h[o], h[o + 1], h[o + 2], h[o + 3]]);
        let f64_at = |o: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&h[o..o + 8]);
            f64::from_le_bytes(b)
        };
        let version = u16_at(8);
        if version != SLC_VERSION {
            return Err(SarError::Format(format!("unsupported version {version}")));
        }
        let antenna = match h[10] {
            1 => Antenna::A1,
            2 => Antenna::A2,
            a => return Err(SarError::Format(format!("bad antenna {a}"))),
        };
        let polarisation = Polarisation::from_code(h[11])
            .ok_or_else(|| SarError::Format(format!("bad polarisation code {}", h[11])))?;
        let lines = u32_at(12) as usize;
        let gates = u32_at(16) as usize;
        let crc = u32_at(20);
        let n = lines
            .checked_mul(gates)
            .filter(|&n| n <= SLC_MAX_SAMPLES)
            .ok_or_else(|| SarError::Format(format!("image {lines}×{gates} too large")))?;
        let mut payload = vec![0u8; n * 8];
        r.read_exact(&mut payload)?;
        if CRC32.checksum(&payload) != crc {
            return Err(SarError::Format("checksum mismatch".into()));
        }
        let data = payload
            .chunks_exact(8)
            .map(|c| {
                C32::new(
                    f32::from_le_bytes([c[0], c[1], c[2], c[3]]),
                    f32::from_le_bytes([c[4], c[5], c[6], c[7]]),
                )
            })
            .collect();
        Ok(Self {
            antenna,
            polarisation,
            lines,
            gates,
            data,
            first_range_m: f64_at(24),
            range_spacing_m: f64_at(32),
            first_azimuth_m: f64_at(40),
            azimuth_spacing_m: f64_at(48),
            wavelength_m: f64_at(56),
            antenna_yz_m: [f64_at(64), f64_at(72)],
            velocity_m_s: f64_at(80),
            range_energy_width_m: f64_at(88),
            azimuth_energy_width_m: f64_at(96),
            reference_height_m: f64_at(104),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Slc {
        Slc {
            antenna: Antenna::A2,
            polarisation: Polarisation::VV,
            lines: 2,
            gates: 3,
            data: (0..6)
                .map(|i| C32::new(i as f32, -(i as f32) * 0.5))
                .collect(),
            first_range_m: 110_000.0,
            range_spacing_m: 2.19,
            first_azimuth_m: -5.0,
            azimuth_spacing_m: 5.0,
            wavelength_m: 0.24,
            antenna_yz_m: [-48_000.0, 100_000.0],
            velocity_m_s: 1600.0,
            range_energy_width_m: 5.97,
            azimuth_energy_width_m: 13.6,
            reference_height_m: 0.0,
        }
    }

    #[test]
    fn round_trip_and_golden_header() {
        let s = sample();
        let mut buf = Vec::new();
        s.write_to(&mut buf).unwrap();
        assert_eq!(buf.len(), SLC_HEADER_LEN + 6 * 8);
        // Golden bytes: magic, version 1, antenna 2, VV = 1, 2 lines, 3 gates.
        assert_eq!(
            &buf[..20],
            &[
                b'U', b'M', b'B', b'R', b'A', b'S', b'L', b'C', 1, 0, 2, 1, 2, 0, 0, 0, 3, 0, 0, 0
            ]
        );
        assert_eq!(&buf[24..32], &110_000.0f64.to_le_bytes());
        assert_eq!(Slc::read_from(&buf[..]).unwrap(), s);
    }

    #[test]
    fn corrupt_files_are_rejected() {
        let mut buf = Vec::new();
        sample().write_to(&mut buf).unwrap();
        let mut bad = buf.clone();
        bad[SLC_HEADER_LEN + 3] ^= 0x40;
        assert!(matches!(Slc::read_from(&bad[..]), Err(SarError::Format(_))));
        let mut bad = buf.clone();
        bad[0] = b'X';
        assert!(Slc::read_from(&bad[..]).is_err());
        assert!(Slc::read_from(&buf[..buf.len() - 1]).is_err());
        let mut bad = buf;
        bad[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(Slc::read_from(&bad[..]).is_err());
    }
}
