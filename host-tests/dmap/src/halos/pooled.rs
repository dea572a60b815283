//! One-position absorbers and halos, and the decisions of issue 50 on them:
//! per position the map's power `P` (its sample sum) and the spread
//! channel's `q` (share of `P` outside the 5x5 core), pooled over small
//! footprints inside the engine's three-row window, and the floor of an
//! ideal detector that knows the defect's footprint (docs/experiments.md,
//! "Pooled decisions for one-position defects"), all in f64.
//!
//! An absorber is a scattering disc whose halo is far wider than the
//! receiver's field ([`ABSORBER_WIDTH`]): the light crossing it leaves the
//! detector, as from a bubble that sends it out of the receiver.

use cvm_core::calibration::histogram::{Histogram, bins};
use cvm_core::calibration::{Rule, rule};
use cvm_core::spread::{CORE_HALF, outside_core};
use cvm_sim::rng::mix;
use cvm_sim::{Config, Scan, Scatterer};

use super::parts::{Geo, HALO_WIDTH, Halo, strongest_beam};

/// Halo rms angle of an absorber: 0.45 rad per axis, against a detector
/// 9 mm across behind a 50 mm lens (0.09 rad from its centre to an edge):
/// at most `erf(4.5 / (22.5 sqrt 2))^2 = 2.5 %` of the light it takes lands
/// anywhere on the detector, spread over every cell.
pub const ABSORBER_WIDTH: f64 = 0.45;

/// What a defect does with the light it takes from a beam.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Sends it out of the receiver: the beam's power drops.
    Absorber,
    /// Sends it into a halo of [`HALO_WIDTH`]: `q` rises.
    Halo,
}

/// Where a one-position disc sits against the beams.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// On a beam's axis.
    Centred,
    /// Half a pitch from two beams of one row.
    BetweenColumns,
    /// Half a pitch from two beams of one column.
    BetweenRows,
}

/// One defect to place: a disc one position across that takes `power` of
/// its strongest beam's power, at raster position `at`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Defect {
    pub kind: Kind,
    pub power: f64,
    pub at: (usize, usize),
    pub place: Place,
}

/// A placed defect: its disc and truth (as [`Halo`]), and the share of each
/// beam's power it takes (`(row, col)`, share), its strongest first.
#[derive(Clone, Debug)]
pub struct Placed {
    pub defect: Defect,
    pub halo: Halo,
    pub beams: Vec<((usize, usize), f64)>,
}

/// Part `k` of `geo` on an `n x n` raster, its laser's per-beam power
/// jitter `laser_rms` (relative rms), with `defects` on it. An error when a
/// defect asks for more of a beam's power than its disc can take.
pub fn defect_part(
    geo: Geo,
    k: u64,
    n: usize,
    laser_rms: f64,
    defects: &[Defect],
) -> Result<(Config, Vec<Placed>), String> {
    let mut cfg = geo.part(k, n);
    cfg.laser.rms = laser_rms;
    let r = cfg.raster;
    let reach = cfg.footprint * r.waist;
    let mut placed = Vec::with_capacity(defects.len());
    for d in defects {
        let (x, y) = r.position(d.at.0, d.at.1);
        let (dx, dy) = match d.place {
            Place::Centred => (0.0, 0.0),
            Place::BetweenColumns => (r.pitch / 2.0, 0.0),
            // Rows run along -y: half-way to the next row.
            Place::BetweenRows => (0.0, -r.pitch / 2.0),
        };
        let width = match d.kind {
            Kind::Absorber => ABSORBER_WIDTH,
            Kind::Halo => HALO_WIDTH,
        };
        let mut disc = Scatterer::across(x + dx, y + dy, 1.0, r.pitch, 1.0, width);
        let most = strongest_beam(&cfg, &disc);
        let share = d.power / most;
        if !(share > 0.0 && share <= 1.0) {
            return Err(format!(
                "a one-position disc at {:?} ({:?}) takes at most {:.1} % of a beam's power, not {:.1} %",
                d.at,
                d.place,
                most * 100.0,
                d.power * 100.0
            ));
        }
        disc.share = share;
        let cells = (0..n * n).map(|p| (p / n, p % n));
        let truth = cells
            .clone()
            .filter(|&(rr, cc)| {
                let (px, py) = r.position(rr, cc);
                (px - disc.x).hypot(py - disc.y) < disc.radius + reach
            })
            .collect();
        let mut beams: Vec<((usize, usize), f64)> = cells
            .filter(|&(rr, cc)| {
                let (px, py) = r.position(rr, cc);
                (px - disc.x).hypot(py - disc.y) <= disc.radius + 3.0 * r.waist
            })
            .map(|(rr, cc)| {
                let (px, py) = r.position(rr, cc);
                ((rr, cc), disc.beam_share(px, py, r.waist))
            })
            .collect();
        beams.sort_by(|a, b| b.1.total_cmp(&a.1));
        placed.push(Placed {
            defect: *d,
            halo: Halo {
                disc,
                size: 1.0,
                truth,
            },
            beams,
        });
    }
    cfg.part.scatterers = placed.iter().map(|p| p.halo.disc).collect();
    Ok((cfg, placed))
}

/// The per-position quantities the engine has in its window, raster order:
/// each map's power `P` (sample sum, counts) and `q` (its share outside the
/// 5x5 core around the brightest cell, a fraction: the spread channel's
/// `Q16` value over 2^16, `cvm_core::spread::outside_core`).
#[derive(Clone, Debug)]
pub struct Quantities {
    pub rows: usize,
    pub cols: usize,
    pub power: Vec<f64>,
    pub q: Vec<f64>,
}

pub fn quantities(scan: &Scan) -> Quantities {
    let cells = scan.j1 * scan.j2;
    let (mut power, mut q) = (Vec::new(), Vec::new());
    for frame in scan.data.chunks_exact(cells) {
        let p: u32 = frame.iter().map(|&v| u32::from(v)).sum();
        power.push(f64::from(p));
        let s = outside_core(frame, scan.j1, scan.j2, CORE_HALF as usize, p);
        q.push(f64::from(s) / 65536.0);
    }
    Quantities {
        rows: scan.rows,
        cols: scan.cols,
        power,
        q,
    }
}

/// Which channel a statistic reads, and its one side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    /// The power lost: `1 - P / R`, `R` the surroundings' mean power (0
    /// when `R = 0`).
    Power,
    /// The share outside the core gained: `q - R`, `R` the surroundings'
    /// mean `q`.
    Spread,
}

impl Channel {
    pub const BOTH: [Channel; 2] = [Channel::Power, Channel::Spread];

    pub fn name(self) -> &'static str {
        match self {
            Channel::Power => "power",
            Channel::Spread => "spread",
        }
    }

    fn values(self, qs: &Quantities) -> &[f64] {
        match self {
            Channel::Power => &qs.power,
            Channel::Spread => &qs.q,
        }
    }

    /// The signed excess of `v` over the reference `r` (positive: the
    /// defect's side).
    fn excess(self, v: f64, r: f64) -> f64 {
        match self {
            Channel::Power if r > 0.0 => 1.0 - v / r,
            Channel::Power => 0.0,
            Channel::Spread => v - r,
        }
    }
}

/// The footprints a position's pooled value takes the largest over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Footprints {
    /// The position alone.
    Single,
    /// The position alone, the horizontal and vertical pairs and the 2x2
    /// quads that hold it.
    All,
}

/// The footprints holding position `(t, c)` that lie in rows `t - 1 ..=
/// t + 1` of a `rows x cols` raster, each as `(r0, r1, c0, c1)` (inclusive).
fn footprints_of(
    t: usize,
    c: usize,
    rows: usize,
    cols: usize,
    set: Footprints,
) -> Vec<(usize, usize, usize, usize)> {
    let mut v = vec![(t, t, c, c)];
    if set == Footprints::Single {
        return v;
    }
    let up = t.checked_sub(1);
    let down = (t + 1 < rows).then_some(t + 1);
    let left = c.checked_sub(1);
    let right = (c + 1 < cols).then_some(c + 1);
    for cc in [left, right].into_iter().flatten() {
        v.push((t, t, cc.min(c), cc.max(c)));
    }
    for rr in [up, down].into_iter().flatten() {
        v.push((rr.min(t), rr.max(t), c, c));
        for cc in [left, right].into_iter().flatten() {
            v.push((rr.min(t), rr.max(t), cc.min(c), cc.max(c)));
        }
    }
    v
}

/// The pooled statistic of footprint `(r0, r1, c0, c1)` with its
/// surroundings the rest of the box of rows `t - 1 ..= t + 1` and columns
/// `c0 - 1 ..= c1 + 1` (clipped to the raster):
/// `excess(mean over the footprint, mean over the surroundings) /
/// sqrt(1/k + 1/m)`, `k` and `m` their sizes.
fn pooled_of(
    values: &[f64],
    t: usize,
    fp: (usize, usize, usize, usize),
    rows: usize,
    cols: usize,
    ch: Channel,
) -> f64 {
    let (r0, r1, c0, c1) = fp;
    let (br0, br1) = (t.saturating_sub(1), (t + 1).min(rows - 1));
    let (bc0, bc1) = (c0.saturating_sub(1), (c1 + 1).min(cols - 1));
    let (mut fs, mut k, mut rs, mut m) = (0.0, 0usize, 0.0, 0usize);
    for r in br0..=br1 {
        for c in bc0..=bc1 {
            let v = values[r * cols + c];
            if (r0..=r1).contains(&r) && (c0..=c1).contains(&c) {
                fs += v;
                k += 1;
            } else {
                rs += v;
                m += 1;
            }
        }
    }
    if k == 0 || m == 0 {
        return 0.0;
    }
    let (f, r) = (fs / k as f64, rs / m as f64);
    ch.excess(f, r) / (1.0 / k as f64 + 1.0 / m as f64).sqrt()
}

/// Every position's pooled value on channel `ch`: the largest statistic
/// over the footprints of `set` that hold it, decided in the window of
/// its own row and the rows above and below; raster order.
pub fn pooled(qs: &Quantities, ch: Channel, set: Footprints) -> Vec<f64> {
    let values = ch.values(qs);
    let (rows, cols) = (qs.rows, qs.cols);
    (0..rows * cols)
        .map(|p| {
            let (t, c) = (p / cols, p % cols);
            footprints_of(t, c, rows, cols, set)
                .into_iter()
                .map(|fp| pooled_of(values, t, fp, rows, cols, ch))
                .fold(f64::MIN, f64::max)
        })
        .collect()
}

/// The ideal detector's weights: each beam's share of its power that the
/// defect takes, as offsets from its strongest beam; beams under 1 % of the
/// strongest are left out.
pub fn pattern(p: &Placed) -> Vec<((isize, isize), f64)> {
    let ((r0, c0), top) = p.beams[0];
    p.beams
        .iter()
        .filter(|b| b.1 >= 0.01 * top)
        .map(|&((r, c), w)| ((r as isize - r0 as isize, c as isize - c0 as isize), w))
        .collect()
}

/// The matched statistic of `pattern` with its strongest beam at `at`:
/// with `R` the mean over the surroundings (the positions within one of
/// the pattern's, not in it; `m` of them), `sum w_i excess(v_i, R) /
/// sqrt(sum w_i^2 + (sum w_i)^2 / m)`. `None` when the pattern leaves the
/// raster.
pub fn matched(
    qs: &Quantities,
    ch: Channel,
    pattern: &[((isize, isize), f64)],
    at: (usize, usize),
) -> Option<f64> {
    let (rows, cols) = (qs.rows as isize, qs.cols as isize);
    let values = ch.values(qs);
    let cell = |(dr, dc): (isize, isize)| {
        let (r, c) = (at.0 as isize + dr, at.1 as isize + dc);
        (r >= 0 && c >= 0 && r < rows && c < cols).then_some((r * cols + c) as usize)
    };
    let mut inside = Vec::with_capacity(pattern.len());
    for &(o, w) in pattern {
        inside.push((cell(o)?, w));
    }
    let mut ring: Vec<usize> = pattern
        .iter()
        .flat_map(|&((dr, dc), _)| {
            (-1..=1).flat_map(move |a| (-1..=1).map(move |b| (dr + a, dc + b)))
        })
        .filter(|o| !pattern.iter().any(|p| p.0 == *o))
        .filter_map(cell)
        .collect();
    ring.sort_unstable();
    ring.dedup();
    if ring.is_empty() {
        return None;
    }
    let m = ring.len() as f64;
    let r = ring.iter().map(|&i| values[i]).sum::<f64>() / m;
    let (mut s, mut w2, mut w1) = (0.0, 0.0, 0.0);
    for (i, w) in inside {
        s += w * ch.excess(values[i], r);
        w2 += w * w;
        w1 += w;
    }
    Some(s / (w2 + w1 * w1 / m).sqrt())
}

/// [`matched`] at every position where the pattern fits, raster order.
pub fn matched_all(qs: &Quantities, ch: Channel, pattern: &[((isize, isize), f64)]) -> Vec<f64> {
    (0..qs.rows * qs.cols)
        .filter_map(|p| matched(qs, ch, pattern, (p / qs.cols, p % qs.cols)))
        .collect()
}

/// Statistics to the tail rule's integers: `2^16` per unit, negatives 0.
pub fn to_fixed(v: f64) -> u32 {
    (v * 65536.0).round().clamp(0.0, u32::MAX as f64) as u32
}

/// The board's tail rule (`Rule::DEFAULT`: one false position in 1000
/// parts) on the values of `parts` reference parts, in the units of the
/// values: a value fires at or above it.
pub fn tail_threshold(parts: &[Vec<f64>]) -> f64 {
    let mut h = Box::new(Histogram::<{ bins(32) }>::new());
    for v in parts.iter().flatten() {
        h.add(to_fixed(*v));
    }
    let ch = rule::channel(&h, &Rule::DEFAULT, parts.len() as u16).expect("reference values");
    f64::from(ch.threshold) / 65536.0
}

/// `n` defects of each `(kind, power, place)` cell, spread over parts of
/// `sites` defects each (sites 13 positions apart on a 39x39 raster): the
/// defects of part `j` in order. `Between` alternates between columns and
/// rows from instance to instance.
pub fn layout(kinds: &[(Kind, &[f64])], between: bool, n: usize) -> Vec<Vec<Defect>> {
    const SITES: [(usize, usize); 9] = [
        (6, 6),
        (6, 19),
        (6, 32),
        (19, 6),
        (19, 19),
        (19, 32),
        (32, 6),
        (32, 19),
        (32, 32),
    ];
    let mut cells = Vec::new();
    for &(kind, powers) in kinds {
        for &power in powers {
            cells.push((kind, power, false));
            if between {
                cells.push((kind, power, true));
            }
        }
    }
    let mut all = Vec::new();
    for i in 0..n {
        for &(kind, power, off) in &cells {
            let place = match (off, i % 2) {
                (false, _) => Place::Centred,
                (true, 0) => Place::BetweenColumns,
                (true, _) => Place::BetweenRows,
            };
            all.push((kind, power, place));
        }
    }
    // Shuffle deterministically so that no site always holds one cell.
    let mut keyed: Vec<(u64, (Kind, f64, Place))> = all
        .into_iter()
        .enumerate()
        .map(|(i, d)| (mix(i as u64 ^ 0x504F_4F4C), d)) // "POOL"
        .collect();
    keyed.sort_by_key(|k| k.0);
    keyed
        .chunks(SITES.len())
        .map(|chunk| {
            chunk
                .iter()
                .zip(SITES)
                .map(|(&(_, (kind, power, place)), at)| Defect {
                    kind,
                    power,
                    at,
                    place,
                })
                .collect()
        })
        .collect()
}
