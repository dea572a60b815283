//! Geometry of the transparent part under test.
//!
//! Every part shape here is convex, so it is modelled as the intersection of
//! a few convex solids (spheres, cylinders, half-spaces). A line then meets
//! the glass in a single interval, entered through the solid with the
//! latest entry and left through the one with the earliest exit; a ray that
//! has left a convex body never meets it again.

use crate::scatter::Scatterer;
use crate::vec3::Vec3;

/// One convex solid of the intersection.
#[derive(Clone, Copy, Debug)]
pub enum Solid {
    /// Points with `normal . p <= offset` (`normal` unit, pointing out of the glass).
    HalfSpace { normal: Vec3, offset: f64 },
    /// Inside of a sphere.
    Sphere { center: Vec3, radius: f64 },
    /// Inside of an infinite cylinder along y through `(cx, *, cz)`.
    CylinderY { cx: f64, cz: f64, radius: f64 },
    /// Inside of an infinite cylinder along z around the optical axis.
    CylinderZ { radius: f64 },
}

/// What a boundary does to light.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    /// Polished optical surface facing the beam.
    Front,
    /// Polished optical surface facing the receiver.
    Back,
    /// Ground rim of the part: light reaching it is lost.
    Edge,
}

/// Parameter interval `[t_in, t_out]` of a line inside a solid, or `None`.
fn solid_interval(s: &Solid, p: Vec3, d: Vec3) -> Option<(f64, f64)> {
    match *s {
        Solid::HalfSpace { normal, offset } => {
            let a = normal.dot(d);
            let b = offset - normal.dot(p);
            if a.abs() < 1e-300 {
                (b >= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY))
            } else if a > 0.0 {
                Some((f64::NEG_INFINITY, b / a))
            } else {
                Some((b / a, f64::INFINITY))
            }
        }
        Solid::Sphere { center, radius } => sphere_interval(center, radius, p, d),
        Solid::CylinderY { cx, cz, radius } => {
            let (ox, oz) = (p.x - cx, p.z - cz);
            quadratic_interval(
                d.x * d.x + d.z * d.z,
                ox * d.x + oz * d.z,
                ox * ox + oz * oz - radius * radius,
            )
        }
        Solid::CylinderZ { radius } => quadratic_interval(
            d.x * d.x + d.y * d.y,
            p.x * d.x + p.y * d.y,
            p.x * p.x + p.y * p.y - radius * radius,
        ),
    }
}

/// Roots of `a t^2 + 2 h t + c = 0` as the inside interval of a quadric whose
/// inside is `< 0`; a line parallel to the axis (`a = 0`) is inside everywhere or nowhere.
fn quadratic_interval(a: f64, h: f64, c: f64) -> Option<(f64, f64)> {
    if a < 1e-300 {
        return (c <= 0.0).then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let disc = h * h - a * c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    // Numerically stable pair of roots.
    let q = -(h + h.signum() * s);
    if q == 0.0 {
        return Some((0.0, 0.0));
    }
    let (r1, r2) = (q / a, c / q);
    Some((r1.min(r2), r1.max(r2)))
}

/// Interval of a line (unit or not) inside a sphere.
pub fn sphere_interval(center: Vec3, radius: f64, p: Vec3, d: Vec3) -> Option<(f64, f64)> {
    let o = p - center;
    quadratic_interval(d.dot(d), o.dot(d), o.dot(o) - radius * radius)
}

/// Outward unit normal of solid `s` at a point `q` on its boundary.
fn solid_normal(s: &Solid, q: Vec3) -> Vec3 {
    match *s {
        Solid::HalfSpace { normal, .. } => normal,
        Solid::Sphere { center, .. } => (q - center).normalized(),
        Solid::CylinderY { cx, cz, .. } => Vec3::new(q.x - cx, 0.0, q.z - cz).normalized(),
        Solid::CylinderZ { .. } => Vec3::new(q.x, q.y, 0.0).normalized(),
    }
}

/// Shape of the part, in millimetres; the beam travels along +z and meets
/// the front vertex at z = 0.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Flat plate of the given thickness and square side.
    Plate { thickness: f64, side: f64 },
    /// Double-convex spherical lens: front and back radii, centre thickness, rim diameter.
    DoubleConvex {
        r1: f64,
        r2: f64,
        thickness: f64,
        diameter: f64,
    },
    /// Plano-convex cylindrical lens, curved in x, flat back; width in x, length in y.
    Cylindrical {
        radius: f64,
        thickness: f64,
        width: f64,
        length: f64,
    },
}

/// A spherical inclusion (an air bubble has `index = 1`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bubble {
    pub center: Vec3,
    pub radius: f64,
    pub index: f64,
}

/// A rough patch of an optical surface (a scratch or dig): within the
/// rectangle `[x0, x1] x [y0, y1]` (projected along z) the local surface
/// normal is tilted by micro-facets of side `facet` whose tilt angles are
/// Gaussian with standard deviation `tilt_sigma` (radians) per axis. The
/// facets are fixed to the surface (hashed from their cell and `seed`), so
/// neighbouring beam positions see the same roughness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceDefect {
    pub face: Face,
    pub x0: f64,
    pub x1: f64,
    pub y0: f64,
    pub y1: f64,
    pub tilt_sigma: f64,
    pub facet: f64,
    pub seed: u64,
}

impl SurfaceDefect {
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.x0 && x <= self.x1 && y >= self.y0 && y <= self.y1
    }

    /// Distance in the xy-plane from a point to the rectangle (0 inside).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        let dx = (self.x0 - x).max(0.0).max(x - self.x1);
        let dy = (self.y0 - y).max(0.0).max(y - self.y1);
        dx.hypot(dy)
    }

    /// Tilt a unit normal by this defect's facet at (x, y).
    fn perturb(&self, n: Vec3, x: f64, y: f64) -> Vec3 {
        let ix = (x / self.facet).floor() as i64;
        let iy = (y / self.facet).floor() as i64;
        let h =
            crate::rng::mix(self.seed ^ crate::rng::mix(ix as u64 ^ crate::rng::mix(iy as u64)));
        let (g1, g2) = crate::rng::gaussian_pair(h);
        // Two tangents of the surface; the normals here are never parallel to y.
        let t1 = n.cross(Vec3::new(0.0, 1.0, 0.0)).normalized();
        let t2 = n.cross(t1);
        (n + t1 * (g1 * self.tilt_sigma).tan() + t2 * (g2 * self.tilt_sigma).tan()).normalized()
    }
}

/// The part: its shape, refractive index, inclusions, surface defects and
/// scattering regions.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    pub shape: Shape,
    pub index: f64,
    pub bubbles: Vec<Bubble>,
    pub defects: Vec<SurfaceDefect>,
    pub scatterers: Vec<Scatterer>,
}

/// Where a line meets the glass boundary.
#[derive(Clone, Copy, Debug)]
pub struct Crossing {
    pub t: f64,
    pub face: Face,
    solid: usize,
}

/// The part compiled into its convex solids.
#[derive(Clone, Debug)]
pub struct Body {
    solids: Vec<(Solid, Face)>,
    pub index: f64,
    pub bubbles: Vec<Bubble>,
    pub defects: Vec<SurfaceDefect>,
    pub scatterers: Vec<Scatterer>,
    /// Smallest z of the glass, for placing the beam source.
    pub z_min: f64,
    /// Largest z of the glass, for placing the receiver.
    pub z_max: f64,
}

impl Part {
    /// Check the numbers make a physical part (positive sizes, index > 0,
    /// inclusions inside the glass).
    pub fn validate(&self) -> Result<(), String> {
        let positive = |v: f64, what: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{what} must be positive, got {v}"))
            }
        };
        positive(self.index, "refractive index")?;
        match self.shape {
            Shape::Plate { thickness, side } => {
                positive(thickness, "plate thickness")?;
                positive(side, "plate side")?;
            }
            Shape::DoubleConvex {
                r1,
                r2,
                thickness,
                diameter,
            } => {
                positive(r1, "front radius")?;
                positive(r2, "back radius")?;
                positive(thickness, "lens thickness")?;
                positive(diameter, "lens diameter")?;
                let h = diameter / 2.0;
                if h >= r1 || h >= r2 {
                    return Err(format!(
                        "lens diameter {diameter} mm needs surface radii above {h} mm"
                    ));
                }
                let sag = |r: f64| r - (r * r - h * h).sqrt();
                if sag(r1) + sag(r2) >= thickness {
                    return Err(format!(
                        "lens of thickness {thickness} mm has a knife edge at diameter {diameter} mm: make it thicker or smaller"
                    ));
                }
            }
            Shape::Cylindrical {
                radius,
                thickness,
                width,
                length,
            } => {
                positive(radius, "cylinder radius")?;
                positive(thickness, "lens thickness")?;
                positive(width, "lens width")?;
                positive(length, "lens length")?;
                let h = width / 2.0;
                if h >= radius || radius - (radius * radius - h * h).sqrt() >= thickness {
                    return Err(format!(
                        "cylindrical lens of width {width} mm does not fit radius {radius} mm and thickness {thickness} mm"
                    ));
                }
            }
        }
        let body = self.body();
        for b in &self.bubbles {
            positive(b.radius, "bubble radius")?;
            positive(b.index, "bubble index")?;
            // The bubble must sit fully inside the glass: check six extreme points.
            let r = b.radius;
            let probes = [
                Vec3::new(r, 0.0, 0.0),
                Vec3::new(-r, 0.0, 0.0),
                Vec3::new(0.0, r, 0.0),
                Vec3::new(0.0, -r, 0.0),
                Vec3::new(0.0, 0.0, r),
                Vec3::new(0.0, 0.0, -r),
            ];
            if !probes.iter().all(|&o| body.contains(b.center + o)) {
                return Err(format!(
                    "bubble at ({}, {}, {}) mm of radius {} mm is not inside the part",
                    b.center.x, b.center.y, b.center.z, b.radius
                ));
            }
        }
        for (i, b) in self.bubbles.iter().enumerate() {
            for c in &self.bubbles[i + 1..] {
                if (b.center - c.center).norm() < b.radius + c.radius {
                    return Err("bubbles overlap".into());
                }
            }
        }
        for d in &self.defects {
            if !(d.x1 > d.x0 && d.y1 > d.y0) {
                return Err("surface defect rectangle is empty".into());
            }
            positive(d.facet, "facet size")?;
            if !(d.tilt_sigma.is_finite() && d.tilt_sigma >= 0.0 && d.tilt_sigma < 0.5) {
                return Err(format!(
                    "facet tilt {} rad must be in [0, 0.5)",
                    d.tilt_sigma
                ));
            }
            if d.face == Face::Edge {
                return Err("surface defects sit on the front or back face".into());
            }
        }
        for s in &self.scatterers {
            s.validate()?;
        }
        Ok(())
    }

    /// Compile the shape into convex solids.
    pub fn body(&self) -> Body {
        let z_axis = Vec3::new(0.0, 0.0, 1.0);
        let (solids, z_max) = match self.shape {
            Shape::Plate { thickness, side } => {
                let h = side / 2.0;
                (
                    vec![
                        (
                            Solid::HalfSpace {
                                normal: -z_axis,
                                offset: 0.0,
                            },
                            Face::Front,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: z_axis,
                                offset: thickness,
                            },
                            Face::Back,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(1.0, 0.0, 0.0),
                                offset: h,
                            },
                            Face::Edge,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(-1.0, 0.0, 0.0),
                                offset: h,
                            },
                            Face::Edge,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(0.0, 1.0, 0.0),
                                offset: h,
                            },
                            Face::Edge,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(0.0, -1.0, 0.0),
                                offset: h,
                            },
                            Face::Edge,
                        ),
                    ],
                    thickness,
                )
            }
            Shape::DoubleConvex {
                r1,
                r2,
                thickness,
                diameter,
            } => (
                vec![
                    (
                        Solid::Sphere {
                            center: Vec3::new(0.0, 0.0, r1),
                            radius: r1,
                        },
                        Face::Front,
                    ),
                    (
                        Solid::Sphere {
                            center: Vec3::new(0.0, 0.0, thickness - r2),
                            radius: r2,
                        },
                        Face::Back,
                    ),
                    (
                        Solid::CylinderZ {
                            radius: diameter / 2.0,
                        },
                        Face::Edge,
                    ),
                ],
                thickness,
            ),
            Shape::Cylindrical {
                radius,
                thickness,
                width,
                length,
            } => {
                let (hw, hl) = (width / 2.0, length / 2.0);
                (
                    vec![
                        (
                            Solid::CylinderY {
                                cx: 0.0,
                                cz: radius,
                                radius,
                            },
                            Face::Front,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: z_axis,
                                offset: thickness,
                            },
                            Face::Back,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(1.0, 0.0, 0.0),
                                offset: hw,
                            },
                            Face::Edge,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(-1.0, 0.0, 0.0),
                                offset: hw,
                            },
                            Face::Edge,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(0.0, 1.0, 0.0),
                                offset: hl,
                            },
                            Face::Edge,
                        ),
                        (
                            Solid::HalfSpace {
                                normal: Vec3::new(0.0, -1.0, 0.0),
                                offset: hl,
                            },
                            Face::Edge,
                        ),
                    ],
                    thickness,
                )
            }
        };
        Body {
            solids,
            index: self.index,
            bubbles: self.bubbles.clone(),
            defects: self.defects.clone(),
            scatterers: self.scatterers.clone(),
            z_min: 0.0,
            z_max,
        }
    }
}

impl Body {
    /// Interval of the line `p + t d` inside the glass with the faces it
    /// crosses there, or `None` if it misses the part.
    pub fn interval(&self, p: Vec3, d: Vec3) -> Option<(Crossing, Crossing)> {
        let mut enter = Crossing {
            t: f64::NEG_INFINITY,
            face: Face::Edge,
            solid: usize::MAX,
        };
        let mut leave = Crossing {
            t: f64::INFINITY,
            face: Face::Edge,
            solid: usize::MAX,
        };
        for (i, (s, face)) in self.solids.iter().enumerate() {
            let (a, b) = solid_interval(s, p, d)?;
            if a > enter.t {
                enter = Crossing {
                    t: a,
                    face: *face,
                    solid: i,
                };
            }
            if b < leave.t {
                leave = Crossing {
                    t: b,
                    face: *face,
                    solid: i,
                };
            }
        }
        (enter.t < leave.t && enter.solid != usize::MAX && leave.solid != usize::MAX)
            .then_some((enter, leave))
    }

    /// Is a point strictly inside the glass?
    pub fn contains(&self, q: Vec3) -> bool {
        match self.interval(q, Vec3::new(0.0, 0.0, 1.0)) {
            Some((a, b)) => a.t < 0.0 && b.t > 0.0,
            None => false,
        }
    }

    /// Outward unit normal where a line crosses the boundary at `q`,
    /// including the micro-facet tilt of any surface defect there.
    pub fn normal(&self, c: &Crossing, q: Vec3) -> Vec3 {
        let n = solid_normal(&self.solids[c.solid].0, q);
        match self
            .defects
            .iter()
            .find(|d| d.face == c.face && d.contains(q.x, q.y))
        {
            Some(d) => d.perturb(n, q.x, q.y),
            None => n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens() -> Part {
        Part {
            shape: Shape::DoubleConvex {
                r1: 100.0,
                r2: 100.0,
                thickness: 5.0,
                diameter: 30.0,
            },
            index: 1.5,
            bubbles: vec![],
            defects: vec![],
            scatterers: vec![],
        }
    }

    #[test]
    fn axial_line_crosses_lens_at_vertices() {
        let b = lens().body();
        let (a, z) = b
            .interval(Vec3::new(0.0, 0.0, -10.0), Vec3::new(0.0, 0.0, 1.0))
            .unwrap();
        assert!((a.t - 10.0).abs() < 1e-12 && a.face == Face::Front);
        assert!((z.t - 15.0).abs() < 1e-12 && z.face == Face::Back);
    }

    #[test]
    fn off_axis_line_meets_sagged_surfaces() {
        // At height h = 10 the sag of an R = 100 surface is 100 - sqrt(100^2 - 10^2).
        let b = lens().body();
        let sag = 100.0 - (100.0f64 * 100.0 - 100.0).sqrt();
        let (a, z) = b
            .interval(Vec3::new(10.0, 0.0, -10.0), Vec3::new(0.0, 0.0, 1.0))
            .unwrap();
        assert!((a.t - (10.0 + sag)).abs() < 1e-12);
        assert!((z.t - (15.0 - sag)).abs() < 1e-12);
    }

    #[test]
    fn line_outside_rim_misses_or_hits_edge() {
        let b = lens().body();
        assert!(
            b.interval(Vec3::new(16.0, 0.0, -10.0), Vec3::new(0.0, 0.0, 1.0))
                .is_none()
        );
        // A slanted line entering through the rim reports the edge face.
        let d = Vec3::new(-1.0, 0.0, 0.05).normalized();
        let (a, _) = b.interval(Vec3::new(20.0, 0.0, 2.5), d).unwrap();
        assert_eq!(a.face, Face::Edge);
    }

    #[test]
    fn validation_rejects_bubble_outside_glass() {
        let mut p = lens();
        p.bubbles.push(Bubble {
            center: Vec3::new(0.0, 0.0, 4.95),
            radius: 0.1,
            index: 1.0,
        });
        assert!(p.validate().is_err());
        p.bubbles[0].center.z = 2.5;
        assert!(p.validate().is_ok());
    }

    #[test]
    fn validation_rejects_knife_edge_lens() {
        let mut p = lens();
        p.shape = Shape::DoubleConvex {
            r1: 100.0,
            r2: 100.0,
            thickness: 2.0,
            diameter: 40.0,
        };
        assert!(p.validate().is_err());
    }
}
