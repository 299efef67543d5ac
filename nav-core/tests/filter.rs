//! The navigation filter on a simulated flight: IMU with bias and noise at 100 Hz, TRN fixes at
//! 1 Hz with 10 % gross outliers. Checks consistency (NEES), outlier gating and accuracy.

use nav_core::filter::{FilterConfig, FixMeasurement, InitialState, NavFilter, UpdateOutcome};
use nav_core::rng::Pcg32;

fn gauss(r: &mut Pcg32) -> f64 {
    let u = (r.next_u32() as f64 + 1.0) / 4_294_967_297.0;
    let v = r.next_u32() as f64 / 4_294_967_296.0;
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

#[test]
fn filter_is_consistent_and_rejects_outliers() {
    let cfg = FilterConfig::default();
    let mut rng = Pcg32::new(2024, 1);
    let dt = 0.01;
    let g = cfg.gravity_mps2;
    // Truth: level flight, speed 20 m/s, turning slowly (yaw rate 0.5°/s), constant altitude.
    let (speed, yaw_rate) = (20.0f64, 0.5f64.to_radians());
    let (mut x, mut y, z, mut yaw) = (0.0f64, 0.0f64, 500.0f64, 0.3f64);
    let (ba, bg) = ([0.004, -0.003, 0.002], [2e-5, -1e-5, 3e-5]);
    let init = InitialState {
        position_m: [x + 20.0, y - 15.0, z + 5.0],
        velocity_mps: [speed * yaw.cos() + 0.5, speed * yaw.sin() - 0.3, 0.0],
        yaw_rad: yaw + 1f64.to_radians(),
        position_sigma_m: 30.0,
        velocity_sigma_mps: 1.0,
        attitude_sigma_rad: 2f64.to_radians(),
        accel_bias_sigma: 0.01,
        gyro_bias_sigma: 1e-4,
    };
    let mut f = NavFilter::new(&init, cfg);
    let (mut in_band, mut checks, mut rejected, mut outliers, mut accepted_outliers) =
        (0, 0, 0, 0, 0);
    let mut last_err = 0.0f64;
    for step in 1..=12_000 {
        // Truth advances (exact for the constant turn at this step size).
        yaw += yaw_rate * dt;
        x += speed * yaw.cos() * dt;
        y += speed * yaw.sin() * dt;
        // Centripetal acceleration in body y (left), gravity reaction in body z.
        let accel = [
            ba[0] + cfg.accel_noise / dt.sqrt() * gauss(&mut rng),
            speed * yaw_rate + ba[1] + cfg.accel_noise / dt.sqrt() * gauss(&mut rng),
            g + ba[2] + cfg.accel_noise / dt.sqrt() * gauss(&mut rng),
        ];
        let gyro = [
            bg[0] + cfg.gyro_noise / dt.sqrt() * gauss(&mut rng),
            bg[1] + cfg.gyro_noise / dt.sqrt() * gauss(&mut rng),
            yaw_rate + bg[2] + cfg.gyro_noise / dt.sqrt() * gauss(&mut rng),
        ];
        f.propagate(dt, accel, gyro).unwrap();
        if step % 100 == 0 {
            let outlier = step % 1000 == 500;
            let (sx, sy) = (5.0, 5.0);
            let mut m = FixMeasurement {
                x_m: x + sx * gauss(&mut rng),
                y_m: y + sy * gauss(&mut rng),
                yaw_rad: yaw + 0.5f64.to_radians() * gauss(&mut rng),
                position_cov_m2: [[sx * sx, 0.0], [0.0, sy * sy]],
                yaw_sigma_rad: 0.5f64.to_radians(),
            };
            if outlier {
                m.x_m += 300.0;
                outliers += 1;
            }
            match f.update_fix(&m).unwrap() {
                UpdateOutcome::Rejected { .. } => rejected += 1,
                UpdateOutcome::Accepted { .. } if outlier => accepted_outliers += 1,
                UpdateOutcome::Accepted { .. } => {}
            }
            f.update_altitude(z + 2.0 * gauss(&mut rng), 2.0).unwrap();
            // NEES of the horizontal position after 20 s of convergence.
            if step > 2000 {
                let p = f.position_m();
                let c = f.horizontal_cov_m2();
                let (ex, ey) = (x - p[0], y - p[1]);
                let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
                let nees =
                    (c[1][1] * ex * ex - (c[0][1] + c[1][0]) * ex * ey + c[0][0] * ey * ey) / det;
                checks += 1;
                // 95 % two-sided band of χ²(2).
                if (0.0506..=7.378).contains(&nees) {
                    in_band += 1;
                }
                last_err = ex.hypot(ey);
            }
        }
    }
    let frac = in_band as f64 / checks as f64;
    println!(
        "seed 2024: {checks} NEES checks, {:.1} % in the 95 % band; {rejected} fixes rejected of {outliers} outliers; final error {last_err:.2} m, yaw error {:.3}°",
        frac * 100.0,
        (f.yaw_rad() - yaw)
            .to_degrees()
            .rem_euclid(360.0)
            .min(360.0 - (f.yaw_rad() - yaw).to_degrees().rem_euclid(360.0))
    );
    assert_eq!(accepted_outliers, 0, "an outlier fix got through");
    assert!(
        rejected <= outliers + 2,
        "too many good fixes rejected: {rejected}"
    );
    assert!(frac >= 0.85, "NEES in band only {frac}");
    assert!(last_err < 6.0);
}

#[test]
fn bad_inputs_are_refused() {
    let mut f = NavFilter::new(
        &InitialState {
            position_m: [0.0; 3],
            velocity_mps: [0.0; 3],
            yaw_rad: 0.0,
            position_sigma_m: 1.0,
            velocity_sigma_mps: 1.0,
            attitude_sigma_rad: 0.1,
            accel_bias_sigma: 0.01,
            gyro_bias_sigma: 1e-4,
        },
        FilterConfig::default(),
    );
    assert!(f.propagate(0.0, [0.0; 3], [0.0; 3]).is_err());
    assert!(f.propagate(5.0, [0.0; 3], [0.0; 3]).is_err());
    assert!(f.propagate(0.01, [f64::NAN, 0.0, 0.0], [0.0; 3]).is_err());
    let m = FixMeasurement {
        x_m: 0.0,
        y_m: 0.0,
        yaw_rad: 0.0,
        position_cov_m2: [[-1.0, 0.0], [0.0, -1.0]],
        yaw_sigma_rad: 0.0,
    };
    assert!(
        f.update_fix(&m).is_err() || matches!(f.update_fix(&m), Ok(UpdateOutcome::Rejected { .. }))
    );
    assert!(f.update_altitude(f64::INFINITY, 1.0).is_err());
    assert!(f.position_m().iter().all(|v| v.is_finite()));
}
