//! What a bench run found, as a table or one JSON object, against the
//! speed targets.

use crate::bench::kernels::{Agreement, Implementation};
use crate::bench::measure::{Measurement, RUNS, machine};
use crate::options::ScoringArgs;

/// Speed targets (issue "Benchmarks and speed targets"): paper kernels,
/// uniform weights, normalised 15x15 maps.
pub const TARGET_RATIO: f64 = 50.0;
pub const TARGET_FIXED: f64 = 300_000.0;

pub fn targets_apply(geometry: (usize, usize), scoring: &ScoringArgs) -> bool {
    geometry == (15, 15)
        && scoring
            .core_config(15, 15)
            .ok()
            .is_some_and(|c| c == cvm_core::Config::paper(c.geometry))
}

/// Everything a bench run found.
pub struct Report {
    pub geometry: (usize, usize),
    pub measurements: Vec<Measurement>,
    pub agreement: Agreement,
    pub targets_apply: bool,
}

impl Report {
    pub fn rate(&self, imp: Implementation) -> f64 {
        self.measurements
            .iter()
            .find(|m| m.implementation == imp)
            .map_or(f64::NAN, |m| m.maps_per_s)
    }

    fn ratio(&self) -> f64 {
        self.rate(Implementation::Fixed) / self.rate(Implementation::Sat)
    }

    fn verdicts(&self) -> Option<(bool, bool)> {
        self.targets_apply.then(|| {
            (
                self.ratio() >= TARGET_RATIO,
                self.rate(Implementation::Fixed) >= TARGET_FIXED,
            )
        })
    }

    pub fn json(&self, scoring: &ScoringArgs) -> serde_json::Value {
        use serde_json::{Map, Value, json};
        let mut rates = Map::new();
        let mut samples = Map::new();
        for m in &self.measurements {
            rates.insert(m.implementation.key().into(), json!(m.maps_per_s));
            samples.insert(
                m.implementation.key().into(),
                json!({"rows": m.rows, "cols": m.cols, "repeats": m.repeats, "runs": m.runs,
                       "min_maps_per_s": m.min, "max_maps_per_s": m.max}),
            );
        }
        let agreement: Map<String, Value> = self
            .agreement
            .deviations
            .iter()
            .map(|(imp, d, tol)| {
                (
                    imp.key().to_string(),
                    json!({"max_abs_diff": d, "allowed": tol}),
                )
            })
            .collect();
        let (nproc, cpu) = machine();
        let targets = match self.verdicts() {
            Some((ratio_ok, rate_ok)) => json!({
                "fixed_over_sat_min": TARGET_RATIO, "fixed_min_maps_per_s": TARGET_FIXED,
                "fixed_over_sat_pass": ratio_ok, "fixed_rate_pass": rate_ok}),
            None => Value::Null,
        };
        let c = scoring;
        json!({
            "geometry": format!("{}x{}", self.geometry.0, self.geometry.1),
            "maps_per_s": rates,
            "fixed_over_sat": self.ratio(),
            "targets": targets,
            "config": {"kernels": format!("{:?}", c.kernels).to_lowercase(),
                       "weights": c.weights.map(|w| format!("{w:?}").to_lowercase()),
                       "bmax": c.bmax, "raw": c.raw},
            "agreement": agreement,
            "samples": samples,
            "threads": 1,
            "machine": {"nproc": nproc, "cpu": cpu},
        })
    }

    pub fn text(&self) -> String {
        use std::fmt::Write;
        let (nproc, cpu) = machine();
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{}x{} maps, one thread, {cpu} ({nproc} logical CPUs); median of up to {RUNS} runs",
            self.geometry.0, self.geometry.1
        );
        let _ = writeln!(
            s,
            "{:<46} {:>12} {:>11} {:>15}",
            "implementation", "maps/s", "us/map", "scan x repeats"
        );
        for m in &self.measurements {
            let _ = writeln!(
                s,
                "{:<46} {:>12.0} {:>11.3} {:>15}",
                format!("{} ({})", m.implementation.label(), m.implementation.key()),
                m.maps_per_s,
                1e6 / m.maps_per_s,
                format!("{}x{} x{}", m.rows, m.cols, m.repeats)
            );
        }
        let _ = writeln!(s, "fixed / sat: {:.1}x", self.ratio());
        match self.verdicts() {
            Some((ratio_ok, rate_ok)) => {
                let pf = |b: bool| if b { "PASS" } else { "FAIL" };
                let _ = writeln!(s, "target fixed >= {TARGET_RATIO}x sat: {}", pf(ratio_ok));
                let _ = writeln!(
                    s,
                    "target fixed >= {TARGET_FIXED:.0} maps/s: {}",
                    pf(rate_ok)
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "targets (>= {TARGET_RATIO}x sat, >= {TARGET_FIXED:.0} maps/s) apply to 15x15, paper kernels, uniform weights"
                );
            }
        }
        s
    }
}
