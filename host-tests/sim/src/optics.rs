//! Interface physics: vector Snell's law, mirror reflection, Fresnel reflectance.

use crate::vec3::Vec3;

/// Refracted direction for unit direction `d` meeting a surface of unit
/// normal `n` that faces the incoming ray (`n . d < 0`), with
/// `eta = n_incident / n_transmitted`. `None` on total internal reflection.
pub fn refract(d: Vec3, n: Vec3, eta: f64) -> Option<Vec3> {
    let cos_i = -n.dot(d);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(d * eta + n * (eta * cos_i - cos_t))
}

/// Mirror reflection of `d` about the plane of unit normal `n` (either orientation).
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * (2.0 * d.dot(n))
}

/// Fresnel power reflectance for unpolarised light (mean of s and p) going
/// from index `n1` into `n2` at incidence cosine `cos_i` (>= 0). Returns 1
/// beyond the critical angle.
pub fn fresnel_reflectance(cos_i: f64, n1: f64, n2: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (n1 / n2).powi(2) * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t);
    0.5 * (rs * rs + rp * rp)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir_at(theta: f64) -> Vec3 {
        Vec3::new(theta.sin(), 0.0, theta.cos())
    }

    #[test]
    fn snell_angle_matches_hand_computation() {
        // 30 deg from air into n = 1.5: sin(t) = 0.5 / 1.5 = 1/3, t = 19.4712 deg.
        let n = Vec3::new(0.0, 0.0, -1.0);
        let t = refract(dir_at(30f64.to_radians()), n, 1.0 / 1.5).unwrap();
        assert!((t.norm() - 1.0).abs() < 1e-12);
        let angle = t.x.atan2(t.z);
        assert!((angle - (1.0f64 / 3.0).asin()).abs() < 1e-12);
        assert!((angle.to_degrees() - 19.471_220_634).abs() < 1e-8);
    }

    #[test]
    fn total_internal_reflection_beyond_critical_angle() {
        // Glass (1.5) to air: critical angle asin(1/1.5) = 41.81 deg.
        let n = Vec3::new(0.0, 0.0, -1.0);
        assert!(refract(dir_at(41.0f64.to_radians()), n, 1.5).is_some());
        assert!(refract(dir_at(42.0f64.to_radians()), n, 1.5).is_none());
        assert_eq!(
            fresnel_reflectance(42.0f64.to_radians().cos(), 1.5, 1.0),
            1.0
        );
        // Just below the critical angle the exit ray grazes the surface.
        let t = refract(dir_at(41.8f64.to_radians()), n, 1.5).unwrap();
        assert!(t.z < 0.05 && t.x > 0.99);
    }

    #[test]
    fn normal_incidence_reflectance_is_4_percent_for_glass() {
        // ((n - 1) / (n + 1))^2 = (0.5 / 2.5)^2 = 0.04, either direction.
        assert!((fresnel_reflectance(1.0, 1.0, 1.5) - 0.04).abs() < 1e-12);
        assert!((fresnel_reflectance(1.0, 1.5, 1.0) - 0.04).abs() < 1e-12);
    }

    #[test]
    fn brewster_angle_kills_p_polarisation() {
        // At Brewster's angle atan(1.5), Rp = 0 so R = Rs / 2, and
        // Rs = ((cos_i - n cos_t)/(cos_i + n cos_t))^2 with t = 90 deg - i.
        let i = 1.5f64.atan();
        let t = std::f64::consts::FRAC_PI_2 - i;
        let rs = ((i.cos() - 1.5 * t.cos()) / (i.cos() + 1.5 * t.cos())).powi(2);
        assert!((fresnel_reflectance(i.cos(), 1.0, 1.5) - rs / 2.0).abs() < 1e-12);
    }

    #[test]
    fn reflection_mirrors_the_normal_component() {
        let d = dir_at(0.3);
        let r = reflect(d, Vec3::new(0.0, 0.0, 1.0));
        assert!((r.x - d.x).abs() < 1e-15 && (r.z + d.z).abs() < 1e-15);
    }
}
