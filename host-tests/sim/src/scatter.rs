//! Scattering defects: a region of the part (a cloud of small inclusions,
//! a haze layer) that sends a share of the light crossing it into a broad
//! halo instead of removing it.
//!
//! A bubble of the paper's sizes acts as a strong diverging ball lens: the
//! light that meets it leaves at angles far beyond the receiver's field and
//! is lost, so what is left on the detector keeps the spot's shape. Many
//! inclusions smaller than the beam behave differently: each deflects a
//! little light by a random small angle, and the sum over the cloud is a
//! forward lobe centred on the undisturbed direction. The detector sees the
//! spot, weakened, on top of a wide, faint halo, so the map changes its
//! shape far more than its position or its power.
//!
//! The halo's angular profile is a Gaussian of rms `width` radians per axis
//! around the direction the light would have had: the small-angle form of
//! a forward-peaked scattering lobe, and the one whose share of every
//! detector cell is exact (the receiver's own point spread is a Gaussian,
//! and the two add in quadrature). The scattering region is a disc in the
//! xy-plane at the front face, so the share a beam loses follows from how
//! much of the beam crosses the disc.

/// A disc of the front face, centred at `(x, y)` mm with `radius` mm, that
/// scatters `share` of the light crossing it into a Gaussian halo of rms
/// `width` radians per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scatterer {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
    /// Fraction (0..=1) of the power crossing the disc that goes into the halo.
    pub share: f64,
    /// Halo rms angle per axis (radians).
    pub width: f64,
}

impl Scatterer {
    /// A disc `positions` raster pitches across (diameter), centred at `(x, y)`.
    pub fn across(x: f64, y: f64, positions: f64, pitch: f64, share: f64, width: f64) -> Self {
        Self {
            x,
            y,
            radius: positions * pitch / 2.0,
            share,
            width,
        }
    }

    /// Is the point `(x, y)` of the front face on the disc?
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (x - self.x).hypot(y - self.y) <= self.radius
    }

    /// Share of a Gaussian beam of 1/e^2 radius `waist` centred on the disc
    /// that ends in the halo: `share * (1 - exp(-2 r^2 / w^2))`.
    pub fn centred_beam_share(&self, waist: f64) -> f64 {
        self.share * (1.0 - (-2.0 * self.radius * self.radius / (waist * waist)).exp())
    }

    /// Share of a Gaussian beam of 1/e^2 radius `waist` whose axis crosses
    /// the front face at `(bx, by)` that ends in the halo: `share` times
    /// the beam's power on the disc, integrated over the disc in polar
    /// coordinates about its centre (midpoint rule, 256 radii x 256
    /// angles: within 1e-5 of the closed form for a centred beam). The
    /// simulator's own beam is cut off at a few waists, which changes this
    /// by far less.
    pub fn beam_share(&self, bx: f64, by: f64, waist: f64) -> f64 {
        const N: usize = 256;
        let (dx, dy) = (self.x - bx, self.y - by);
        let s2 = waist * waist / 4.0; // sigma^2 of the intensity, sigma = waist / 2
        let (dr, dt) = (self.radius / N as f64, std::f64::consts::TAU / N as f64);
        let mut on = 0.0;
        for i in 0..N {
            let r = (i as f64 + 0.5) * dr;
            for j in 0..N {
                let t = (j as f64 + 0.5) * dt;
                let (x, y) = (dx + r * t.cos(), dy + r * t.sin());
                on += (-(x * x + y * y) / (2.0 * s2)).exp() * r;
            }
        }
        self.share * on * dr * dt / (std::f64::consts::TAU * s2)
    }

    pub fn validate(&self) -> Result<(), String> {
        if !(self.x.is_finite() && self.y.is_finite()) {
            return Err("scatterer centre must be finite".into());
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(format!(
                "scatterer radius must be positive, got {}",
                self.radius
            ));
        }
        if !(self.share.is_finite() && (0.0..=1.0).contains(&self.share)) {
            return Err(format!(
                "scattered share must be in [0, 1], got {}",
                self.share
            ));
        }
        // Beyond about 0.5 rad the small-angle lobe stops describing light
        // that still reaches a receiving lens.
        if !(self.width.is_finite() && self.width > 0.0 && self.width < 0.5) {
            return Err(format!(
                "halo width must be in (0, 0.5) rad, got {}",
                self.width
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disc_size_and_centred_share() {
        // Three pitches of 0.334 mm across: radius 0.501 mm. A beam of
        // waist 0.25 mm centred on it has 1 - exp(-2 * 0.501^2 / 0.0625) =
        // 0.999672 of its power on the disc.
        let s = Scatterer::across(1.0, -2.0, 3.0, 0.334, 0.3, 0.06);
        assert!((s.radius - 0.501).abs() < 1e-15);
        assert!(s.contains(1.5, -2.0) && !s.contains(1.0, -2.51));
        let want = 0.3 * (1.0 - (-2.0 * 0.501f64 * 0.501 / 0.0625).exp());
        assert!((s.centred_beam_share(0.25) - want).abs() < 1e-15);
        assert!((want - 0.299_902).abs() < 1e-6);
        assert!(s.validate().is_ok());
    }

    #[test]
    fn beam_share_off_the_disc_centre() {
        // One pitch across (radius 0.167 mm), waist 0.25 mm.
        let s = Scatterer::across(0.3, -0.2, 1.0, 0.334, 0.1, 0.06);
        let centred = s.centred_beam_share(0.25);
        assert!((s.beam_share(0.3, -0.2, 0.25) - centred).abs() < 1e-5);
        assert!((centred - 0.059).abs() < 5e-4, "{centred}");
        // 151 µm off: 37.2 % of the beam crosses the disc (an independent
        // 400 x 400 Cartesian grid over +-1 mm gives 0.372).
        let off = s.beam_share(0.3 + 0.151, -0.2, 0.25);
        assert!((off - 0.0372).abs() < 3e-4, "{off}");
        // The same in any direction, and less further out.
        let diag = 0.151 / 2f64.sqrt();
        assert!((s.beam_share(0.3 - diag, -0.2 + diag, 0.25) - off).abs() < 1e-6);
        assert!(s.beam_share(0.3, -0.2 - 0.236, 0.25) < off);
        assert!(s.beam_share(3.0, 3.0, 0.25) < 1e-12);
    }

    #[test]
    fn limits_are_checked() {
        let ok = Scatterer::across(0.0, 0.0, 1.0, 0.334, 0.1, 0.06);
        for bad in [
            Scatterer { share: 1.5, ..ok },
            Scatterer { share: -0.1, ..ok },
            Scatterer { radius: 0.0, ..ok },
            Scatterer { width: 0.0, ..ok },
            Scatterer {
                width: f64::NAN,
                ..ok
            },
            Scatterer {
                x: f64::INFINITY,
                ..ok
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}
