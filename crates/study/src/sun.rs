//! Where the sun stands: NOAA's solar position algorithm (the equations of
//! NOAA's solar calculator spreadsheet, after Meeus, *Astronomical
//! Algorithms*), accurate to about 0.01° for 1800–2100, and the sun's
//! direction in the vehicle's frame.
//!
//! The vehicle frame is the cockpit's: metres, +Y up, the driver looks
//! along -Z, +X is to the driver's right. Azimuths relative to the vehicle
//! count clockwise seen from above, from straight ahead: 0° ahead, 90° to
//! the right, 180° behind, 270° to the left.

use glam::Vec3;

/// The sun seen from a place on the earth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolarPosition {
    /// Degrees clockwise from true north (90° east).
    pub azimuth_deg: f64,
    /// Degrees above the horizon, with the atmosphere's refraction.
    pub elevation_deg: f64,
    /// The sun's apparent declination in degrees (for checks against
    /// almanac values).
    pub declination_deg: f64,
    /// The equation of time in minutes (apparent minus mean solar time).
    pub equation_of_time_min: f64,
}

/// The Julian day of a UTC instant given in seconds since 1970-01-01T00:00Z.
pub fn julian_day(unix_seconds: f64) -> f64 {
    unix_seconds / 86_400.0 + 2_440_587.5
}

/// The sun's position at `unix_seconds` (UTC) seen from `latitude_deg`
/// (north positive) and `longitude_deg` (east positive).
pub fn solar_position(unix_seconds: f64, latitude_deg: f64, longitude_deg: f64) -> SolarPosition {
    let t = (julian_day(unix_seconds) - 2_451_545.0) / 36_525.0;
    let mean_longitude = (280.46646 + t * (36_000.769_83 + t * 0.000_303_2)).rem_euclid(360.0);
    let mean_anomaly = 357.52911 + t * (35_999.050_29 - 0.000_153_7 * t);
    let eccentricity = 0.016_708_634 - t * (0.000_042_037 + 0.000_000_126_7 * t);
    let m = mean_anomaly.to_radians();
    let centre = m.sin() * (1.914_602 - t * (0.004_817 + 0.000_014 * t))
        + (2.0 * m).sin() * (0.019_993 - 0.000_101 * t)
        + (3.0 * m).sin() * 0.000_289;
    let omega = (125.04 - 1934.136 * t).to_radians();
    let apparent_longitude = mean_longitude + centre - 0.00569 - 0.00478 * omega.sin();
    let mean_obliquity =
        23.0 + (26.0 + (21.448 - t * (46.815 + t * (0.00059 - t * 0.001_813))) / 60.0) / 60.0;
    let obliquity = (mean_obliquity + 0.00256 * omega.cos()).to_radians();
    let declination = (obliquity.sin() * apparent_longitude.to_radians().sin()).asin();

    let y = (obliquity / 2.0).tan().powi(2);
    let l0 = mean_longitude.to_radians();
    let e = eccentricity;
    let equation_of_time_min = 4.0
        * (y * (2.0 * l0).sin() - 2.0 * e * m.sin() + 4.0 * e * y * m.sin() * (2.0 * l0).cos()
            - 0.5 * y * y * (4.0 * l0).sin()
            - 1.25 * e * e * (2.0 * m).sin())
        .to_degrees();

    // True solar time in minutes, then the hour angle (0 at solar noon,
    // positive in the afternoon).
    let minutes_of_day = unix_seconds.rem_euclid(86_400.0) / 60.0;
    let solar_minutes =
        (minutes_of_day + equation_of_time_min + 4.0 * longitude_deg).rem_euclid(1440.0);
    let hour_angle = (solar_minutes / 4.0 - 180.0).to_radians();

    let latitude = latitude_deg.to_radians();
    let cos_zenith = (latitude.sin() * declination.sin()
        + latitude.cos() * declination.cos() * hour_angle.cos())
    .clamp(-1.0, 1.0);
    let elevation = 90.0 - cos_zenith.acos().to_degrees();
    // Measured from south towards west, then turned to north-based.
    let from_south = hour_angle
        .sin()
        .atan2(hour_angle.cos() * latitude.sin() - declination.tan() * latitude.cos());
    SolarPosition {
        azimuth_deg: (from_south.to_degrees() + 180.0).rem_euclid(360.0),
        elevation_deg: elevation + refraction_deg(elevation),
        declination_deg: declination.to_degrees(),
        equation_of_time_min,
    }
}

/// NOAA's approximation of the atmosphere's refraction at a true elevation.
fn refraction_deg(elevation_deg: f64) -> f64 {
    let e = elevation_deg;
    let tan = e.to_radians().tan();
    let arc_seconds = if e > 85.0 {
        0.0
    } else if e > 5.0 {
        58.1 / tan - 0.07 / tan.powi(3) + 0.000_086 / tan.powi(5)
    } else if e > -0.575 {
        1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)))
    } else {
        -20.772 / tan
    };
    arc_seconds / 3600.0
}

/// The azimuth relative to a vehicle driving towards compass `heading_deg`
/// (0° north, 90° east), in [0°, 360°).
pub fn relative_azimuth_deg(azimuth_deg: f64, heading_deg: f64) -> f64 {
    (azimuth_deg - heading_deg).rem_euclid(360.0)
}

/// The unit vector from the vehicle towards the sun at `azimuth_deg`
/// relative to the vehicle and `elevation_deg` above the horizon; a
/// directional light's direction is its negative.
pub fn direction_to_sun(azimuth_deg: f32, elevation_deg: f32) -> Vec3 {
    let (sin_az, cos_az) = azimuth_deg.to_radians().sin_cos();
    let (sin_el, cos_el) = elevation_deg.to_radians().sin_cos();
    // Ahead is -Z, right is +X.
    Vec3::new(cos_el * sin_az, sin_el, -cos_el * cos_az).normalize()
}

/// [`direction_to_sun`] backwards: (azimuth relative to the vehicle in
/// [0°, 360°), elevation) of a direction towards the sun.
pub fn vehicle_angles(to_sun: Vec3) -> (f32, f32) {
    let d = to_sun.normalize_or_zero();
    let azimuth = d.x.atan2(-d.z).to_degrees().rem_euclid(360.0);
    let elevation = d.y.clamp(-1.0, 1.0).asin().to_degrees();
    (azimuth, elevation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_job::study::UtcTime;

    fn seconds(y: i32, mo: u32, d: u32, h: u32, mi: u32, s: u32, offset_min: i32) -> f64 {
        UtcTime::from_civil(y, mo, d, h, mi, s, offset_min)
            .expect("a valid date")
            .unix_seconds as f64
    }

    /// The test case of the NREL SPA paper (Reda & Andreas 2004, NREL/TP-560-34302,
    /// appendix A.5): 2003-10-17 12:30:30 local time at -7 h, 39.742476° N,
    /// 105.1786° W. SPA gives Julian day 2452930.312847, zenith 50.11162°
    /// (with refraction at 820 mbar, 11 °C) and azimuth 194.34024°.
    #[test]
    fn the_spa_paper_test_case_within_a_tenth_of_a_degree() {
        let t = seconds(2003, 10, 17, 12, 30, 30, -7 * 60);
        assert!((julian_day(t) - 2_452_930.312_847).abs() < 1e-6);
        let p = solar_position(t, 39.742476, -105.1786);
        assert!((p.elevation_deg - (90.0 - 50.11162)).abs() < 0.1, "{p:?}");
        assert!((p.azimuth_deg - 194.34024).abs() < 0.1, "{p:?}");
    }

    /// Meeus, Astronomical Algorithms (2nd ed.), examples 25.a and 28.a:
    /// on 1992-10-13 at 0 h TD the sun's apparent declination is
    /// -7°47'06" (-7.78507°) and the equation of time 13 min 42.6 s.
    #[test]
    fn meeus_declination_and_equation_of_time() {
        // TD - UT was about 59 s in 1992.
        let t = seconds(1992, 10, 13, 0, 0, 0, 0) - 59.0;
        let p = solar_position(t, 0.0, 0.0);
        assert!((p.declination_deg - -7.78507).abs() < 0.01, "{p:?}");
        // 0.1° of hour angle is 0.4 minutes.
        assert!(
            (p.equation_of_time_min - (13.0 + 42.6 / 60.0)).abs() < 0.4,
            "{p:?}"
        );
    }

    /// At the March 2024 equinox (2024-03-20 03:06 UTC) the declination is
    /// zero: where it is solar noon then, the sun stands 42° high, due
    /// south, at 48° N (plus 0.02° of refraction) and in the zenith on the
    /// equator.
    #[test]
    fn the_equinox_sun_at_noon() {
        let equinox = seconds(2024, 3, 20, 3, 6, 0, 0);
        let p = solar_position(equinox, 0.0, 0.0);
        assert!(p.declination_deg.abs() < 0.01, "{p:?}");
        let noon_longitude = (720.0 - (3.0 * 60.0 + 6.0) - p.equation_of_time_min) / 4.0;
        let north = solar_position(equinox, 48.0, noon_longitude);
        assert!((north.elevation_deg - 42.0).abs() < 0.1, "{north:?}");
        assert!((north.azimuth_deg - 180.0).abs() < 0.1, "{north:?}");
        let equator = solar_position(equinox, 0.0, noon_longitude);
        assert!(equator.elevation_deg > 89.9, "{equator:?}");
    }

    #[test]
    fn vehicle_directions_follow_the_cockpit_axes() {
        let check = |az: f32, el: f32, expected: Vec3| {
            let d = direction_to_sun(az, el);
            assert!((d - expected).length() < 1e-6, "{az} {el}: {d}");
            let (a, e) = vehicle_angles(d);
            assert!((a - az.rem_euclid(360.0)).abs() < 1e-3 && (e - el).abs() < 1e-3);
        };
        check(0.0, 0.0, Vec3::NEG_Z);
        check(90.0, 0.0, Vec3::X);
        check(180.0, 0.0, Vec3::Z);
        check(270.0, 0.0, Vec3::NEG_X);
        check(270.0, 45.0, Vec3::new(-1.0, 1.0, 0.0).normalize());
        // A vehicle driving east has the noon sun (south) on its right.
        assert_eq!(relative_azimuth_deg(180.0, 90.0), 90.0);
        assert_eq!(relative_azimuth_deg(10.0, 350.0), 20.0);
    }
}
