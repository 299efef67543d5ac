//! Crater size–frequency distribution (SFD) of the synthetic surfaces.
//!
//! Observed cumulative density `N_obs(>D) = min(N_prod(>D, T), N_eq(>D))` per km², with
//! - `N_prod`: the Neukum production function (Neukum, Ivanov & Hartmann 2001, Space Sci. Rev. 96,
//!   Table 1: an 11th-degree polynomial in log10 D, valid 10 m–300 km), scaled to a surface age T
//!   by the Neukum (1983) lunar chronology `N(>1 km) = 5.44e-14 (e^{6.93 T} − 1) + 8.38e-4 T`;
//! - `N_eq`: the empirical equilibrium (steady-state) density of small craters on old lunar
//!   surfaces, `N_eq(>D) = 10^-1.1 D^-2` (D in km; Trask 1966), about 5 % of geometric saturation.
//!
//! The model counts are the craters *seen*. In steady state their degradation states are spread
//! evenly between fresh and barely visible, so each crater gets a uniform fraction `u_age` of its
//! visibility lifetime (the time diffusion takes to smooth it away, capped by the surface age; see
//! `crater.rs`).

use rand::RngExt;

/// Neukum et al. (2001) NPF coefficients a0..a11 for the Moon, cumulative density per km² at
/// 1 Gyr-equivalent with D in km.
const NPF: [f64; 12] = [
    -3.0876, -3.557528, 0.781027, 1.021521, -0.156012, -0.444058, 0.019977, 0.086850, -0.005874,
    -0.006809, 8.25e-4, 5.54e-5,
];

/// Equilibrium density coefficient, per km² at D = 1 km (Trask 1966: 10^-1.1).
const EQ_COEFF_PER_KM2: f64 = 0.079_432_823_472_428_15;

/// Cumulative production density `N(>D)` per km² for surface age `age_gyr`, `d_km` in km.
pub fn n_production_per_km2(d_km: f64, age_gyr: f64) -> f64 {
    let x = d_km.log10();
    let mut poly = 0.0;
    for a in NPF.iter().rev() {
        poly = poly * x + a;
    }
    10f64.powf(poly - NPF[0]) * n1_per_km2(age_gyr)
}

/// Neukum (1983) chronology: cumulative density of craters ≥ 1 km per km² after `age_gyr`.
pub fn n1_per_km2(age_gyr: f64) -> f64 {
    5.44e-14 * ((6.93 * age_gyr).exp() - 1.0) + 8.38e-4 * age_gyr
}

/// Present-day production rate of craters ≥ 1 km, per km² per Gyr (the linear term of the
/// Neukum 1983 chronology).
pub const N1_RATE_NOW_PER_KM2_GYR: f64 = 8.38e-4;

/// Impact-flux-equivalent age in Gyr: the time the present flux would need to make the crater
/// density of a surface `age_gyr` old. Degradation by small impacts (diffusion) runs with the
/// flux, which was far higher before ~3.5 Gyr ago, so diffusion clocks use this age.
pub fn flux_equivalent_age_gyr(age_gyr: f64) -> f64 {
    n1_per_km2(age_gyr) / N1_RATE_NOW_PER_KM2_GYR
}

/// Empirical equilibrium cumulative density per km² (Trask 1966).
pub fn n_equilibrium_per_km2(d_km: f64) -> f64 {
    EQ_COEFF_PER_KM2 / (d_km * d_km)
}

/// Observed cumulative density per km²: production capped by equilibrium.
pub fn n_observed_per_km2(d_km: f64, age_gyr: f64) -> f64 {
    n_production_per_km2(d_km, age_gyr).min(n_equilibrium_per_km2(d_km))
}

/// A sampled crater (map metres, window frame of the main crater).
#[derive(Debug, Clone, Copy)]
pub struct CraterDraw {
    /// Rim diameter in metres.
    pub d_m: f64,
    /// Centre x in metres.
    pub x_m: f64,
    /// Centre y in metres.
    pub y_m: f64,
    /// Age as a uniform fraction of the crater's visibility lifetime, [0, 1).
    pub u_age: f64,
    /// Uniform random number in [0, 1) for per-crater morphometric scatter.
    pub u_shape: f64,
    /// Second uniform random number for scatter.
    pub u_rim: f64,
    /// Uniform random number for thinning where craters live shorter (steep slopes).
    pub u_keep: f64,
}

/// Inverse-CDF table of log10 D over `[d_min, d_max]` for `N_obs`.
struct SizeTable {
    log_d: Vec<f64>,
    cum: Vec<f64>,
}

impl SizeTable {
    fn new(d_min_km: f64, d_max_km: f64, age_gyr: f64) -> Self {
        const STEPS: usize = 256;
        let (l0, l1) = (d_min_km.log10(), d_max_km.log10());
        let log_d: Vec<f64> = (0..=STEPS)
            .map(|i| l0 + (l1 - l0) * i as f64 / STEPS as f64)
            .collect();
        let n_max = n_observed_per_km2(d_max_km, age_gyr);
        // Fraction of craters in [d_min, d_max] that are smaller than D (monotone increasing).
        let cum = log_d
            .iter()
            .map(|&l| n_observed_per_km2(10f64.powf(l), age_gyr) - n_max)
            .collect();
        Self { log_d, cum }
    }

    /// Diameter (km) whose cumulative count above it is `u` times the total.
    fn sample(&self, u: f64) -> f64 {
        let total = self.cum.first().copied().unwrap_or(0.0);
        10f64.powf(invert_descending(&self.cum, &self.log_d, u * total))
    }
}

/// The abscissa at which a tabulated decreasing cumulative count `cum` (over abscissae `x`,
/// same length ≥ 2) falls to `target`, linearly interpolated within its bracket: the inverse-CDF
/// step of the size tables.
pub(crate) fn invert_descending(cum: &[f64], x: &[f64], target: f64) -> f64 {
    let n = cum.len().min(x.len());
    if n < 2 {
        return x.first().copied().unwrap_or(0.0);
    }
    let i = cum[..n].partition_point(|&c| c > target).clamp(1, n - 1);
    let (c0, c1) = (cum[i - 1], cum[i]);
    let t = if c0 > c1 {
        (c0 - target) / (c0 - c1)
    } else {
        0.0
    };
    x[i - 1] + t * (x[i] - x[i - 1])
}

/// Draw the craters of a square region `[x_min, x_min + side] × [y_min, y_min + side]` (metres)
/// with diameters in `[d_min_m, d_max_m]`.
pub fn draw_craters<R: rand::Rng>(
    rng: &mut R,
    x_min: f64,
    y_min: f64,
    side_m: f64,
    d_min_m: f64,
    d_max_m: f64,
    age_gyr: f64,
) -> Vec<CraterDraw> {
    if !(d_max_m > d_min_m && d_min_m > 0.0 && side_m > 0.0) {
        return Vec::new();
    }
    let area_km2 = (side_m / 1000.0).powi(2);
    let expected = (n_observed_per_km2(d_min_m / 1000.0, age_gyr)
        - n_observed_per_km2(d_max_m / 1000.0, age_gyr))
        * area_km2;
    // Poisson count via its normal approximation for large means (determinism is what matters,
    // and the relative error of the count is ~1/sqrt(N)).
    let count = poisson(rng, expected);
    let table = SizeTable::new(d_min_m / 1000.0, d_max_m / 1000.0, age_gyr);
    (0..count)
        .map(|_| CraterDraw {
            d_m: table.sample(rng.random::<f64>()) * 1000.0,
            x_m: x_min + side_m * rng.random::<f64>(),
            y_m: y_min + side_m * rng.random::<f64>(),
            u_age: rng.random::<f64>(),
            u_shape: rng.random::<f64>(),
            u_rim: rng.random::<f64>(),
            u_keep: rng.random::<f64>(),
        })
        .collect()
}

/// Poisson-distributed count with mean `lambda` (Knuth for small means, rounded normal for
/// large ones).
fn poisson<R: rand::Rng>(rng: &mut R, lambda: f64) -> usize {
    if lambda.is_nan() || lambda <= 0.0 {
        return 0;
    }
    if lambda < 30.0 {
        let limit = (-lambda).exp();
        let mut k = 0usize;
        let mut p = 1.0;
        loop {
            p *= rng.random::<f64>();
            if p <= limit {
                return k;
            }
            k += 1;
        }
    }
    let n = lambda + lambda.sqrt() * std_normal(rng);
    n.round().max(0.0) as usize
}

/// Standard normal deviate (Box–Muller).
pub fn std_normal<R: rand::Rng>(rng: &mut R) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npf_matches_published_anchor_points() {
        // By construction N(>1 km) equals the chronology value.
        let t = 3.5;
        assert!((n_production_per_km2(1.0, t) / n1_per_km2(t) - 1.0).abs() < 1e-12);
        // Chronology: ~3.2e-3 per km² at 3.2 Gyr… spot-check monotonicity and the 1 Gyr value.
        assert!((n1_per_km2(1.0) - 8.38e-4).abs() < 1e-5);
        // The NPF is steep at small D: cumulative slope between 20 and 100 m is about −3.
        let s = (n_production_per_km2(0.1, 1.0) / n_production_per_km2(0.02, 1.0)).log10()
            / (0.1f64 / 0.02).log10();
        assert!((-3.8..-2.5).contains(&s), "slope {s}");
        // Equilibrium caps small craters on old surfaces.
        assert_eq!(n_observed_per_km2(0.02, 3.9), n_equilibrium_per_km2(0.02));
    }

    #[test]
    fn sampled_sizes_follow_the_model() {
        use rand::SeedableRng;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let c = draw_craters(&mut rng, 0.0, 0.0, 4000.0, 15.0, 2000.0, 3.15);
        let n = c.len() as f64;
        let expected = (n_observed_per_km2(0.015, 3.15) - n_observed_per_km2(2.0, 3.15)) * 16.0;
        assert!(
            (n - expected).abs() < 4.0 * expected.sqrt(),
            "{n} vs {expected}"
        );
        let big = c.iter().filter(|k| k.d_m > 60.0).count() as f64;
        let exp_big = (n_observed_per_km2(0.06, 3.15) - n_observed_per_km2(2.0, 3.15)) * 16.0;
        assert!(
            (big - exp_big).abs() < 4.0 * exp_big.sqrt() + 2.0,
            "{big} vs {exp_big}"
        );
    }
}
