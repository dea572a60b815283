//! The parts of docs/spread-study.md: per geometry a part drawn from a
//! seed (its own lens and raster place), and scattering discs placed on it.

use cvm_sim::rng::mix;
use cvm_sim::{Config, Scatterer, preset};

/// Halo rms angle: the forward lobe of inclusions of about ten wavelengths
/// (docs/spread-study.md).
pub const HALO_WIDTH: f64 = 0.06;

/// A number in [0, 1) from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Geo {
    /// The prototype's 9x9 detector and cylindrical lens.
    Nine,
    /// The paper-sim lens on a 15x15 detector with a 300 µm spot.
    Fifteen,
}

impl Geo {
    pub const BOTH: [Geo; 2] = [Geo::Nine, Geo::Fifteen];

    pub fn name(self) -> &'static str {
        match self {
            Geo::Nine => "9x9",
            Geo::Fifteen => "15x15",
        }
    }

    /// Part `k`, defect-free, on a `n x n` raster: the study's draw (the
    /// same lens radius or raster centre and seed `1000 + k`).
    pub fn part(self, k: u64, n: usize) -> Config {
        let h = mix(k ^ 0x5350_5245_4144); // "SPREAD"
        let (a, b) = (unit(h), unit(mix(h)));
        let mut cfg = match self {
            Geo::Nine => {
                let mut c = preset::prototype(true);
                // Radii 55-75 mm keep the spot on the array across the raster.
                if let cvm_sim::Shape::Cylindrical { radius, .. } = &mut c.part.shape {
                    *radius = 55.0 + 20.0 * a;
                }
                c.raster.center = (2.0 * b - 1.0, 6.0 * a - 3.0);
                c
            }
            Geo::Fifteen => {
                let mut c = preset::paper_sim(true);
                c.receiver.spot = 0.3;
                c.raster.center = (80.0 * a - 40.0, 80.0 * b - 40.0);
                c
            }
        };
        cfg.raster.rows = n;
        cfg.raster.cols = n;
        cfg.seed = 1000 + k;
        cfg
    }
}

/// One scattering disc and the positions its truth marks.
#[derive(Clone, Debug)]
pub struct Halo {
    pub disc: Scatterer,
    /// Diameter in raster positions.
    pub size: f64,
    /// `(row, col)` of the positions whose beam reaches the disc (the
    /// simulator's footprint rule: within `footprint * waist` of its rim).
    pub truth: Vec<(usize, usize)>,
}

/// Part `k` of `geo` on an `n x n` raster with one disc of `size`
/// positions per entry of `shares`, centred on the positions `at`
/// (`(row, col)`) and moved off them by up to half a pitch each way.
pub fn halo_part(
    geo: Geo,
    k: u64,
    n: usize,
    size: f64,
    shares: &[f64],
    at: &[(usize, usize)],
) -> (Config, Vec<Halo>) {
    let mut cfg = geo.part(k, n);
    let pitch = cfg.raster.pitch;
    let reach = cfg.footprint * cfg.raster.waist;
    let halos: Vec<Halo> = shares
        .iter()
        .zip(at)
        .enumerate()
        .map(|(i, (&share, &(row, col)))| {
            let (x, y) = cfg.raster.position(row, col);
            let h = mix(k.wrapping_mul(31) ^ i as u64 ^ 0x4841_4C4F); // "HALO"
            let (dx, dy) = ((unit(h) - 0.5) * pitch, (unit(mix(h)) - 0.5) * pitch);
            let disc = Scatterer::across(x + dx, y + dy, size, pitch, share, HALO_WIDTH);
            let truth = (0..n * n)
                .map(|p| (p / n, p % n))
                .filter(|&(r, c)| {
                    let (px, py) = cfg.raster.position(r, c);
                    (px - disc.x).hypot(py - disc.y) < disc.radius + reach
                })
                .collect();
            Halo { disc, size, truth }
        })
        .collect();
    cfg.part.scatterers = halos.iter().map(|h| h.disc).collect();
    (cfg, halos)
}

/// The largest share of one beam's power that `disc` sends into its halo,
/// over the beams of `cfg`'s raster (`Scatterer::beam_share`). Beams whose
/// axis is more than three waists from the disc's rim put less than
/// `e^-18` of their power on it and are skipped.
pub fn strongest_beam(cfg: &Config, disc: &Scatterer) -> f64 {
    let r = &cfg.raster;
    let reach = disc.radius + 3.0 * r.waist;
    (0..r.rows * r.cols)
        .map(|p| r.position(p / r.cols, p % r.cols))
        .filter(|&(x, y)| (x - disc.x).hypot(y - disc.y) <= reach)
        .map(|(x, y)| disc.beam_share(x, y, r.waist))
        .fold(0.0, f64::max)
}

/// [`halo_part`] with each halo's strength given as the share of a beam's
/// power it takes: each disc's share of the light crossing it is set so
/// that the beam putting the most into its halo ([`strongest_beam`]) puts
/// exactly `powers[i]`. A disc off the beams needs a larger share than one
/// centred on a beam; a share above 1 (a power no beam can lose to this
/// disc) is an error.
pub fn halo_part_of_beam_power(
    geo: Geo,
    k: u64,
    n: usize,
    size: f64,
    powers: &[f64],
    at: &[(usize, usize)],
) -> Result<(Config, Vec<Halo>), String> {
    let ones = vec![1.0; powers.len()];
    let (mut cfg, mut halos) = halo_part(geo, k, n, size, &ones, at);
    for (h, &p) in halos.iter_mut().zip(powers) {
        let most = strongest_beam(&cfg, &h.disc);
        let share = p / most;
        if !(share > 0.0 && share <= 1.0) {
            return Err(format!(
                "a disc of {size} positions at ({:.3}, {:.3}) mm takes at most {:.1} % of a beam's power, not {:.1} %",
                h.disc.x,
                h.disc.y,
                most * 100.0,
                p * 100.0
            ));
        }
        h.disc.share = share;
    }
    cfg.part.scatterers = halos.iter().map(|h| h.disc).collect();
    Ok((cfg, halos))
}
