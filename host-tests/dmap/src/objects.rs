//! Object-level evaluation (`dmap eval`): defects as connected components
//! (8-neighbourhood) of the truth mask and of the thresholded score map,
//! as an integrator sees them: which defects were found, which objects are
//! false, and how well each found object's extent matches its defect.
//!
//! A position is detected when its score reaches the threshold (`>=`, the
//! board's rule). A truth component is found when some detected object
//! shares a position with it; its detected extent is that of the union of
//! those objects (so a defect split in two shows as `objects: 2`). A
//! detected object that shares no position with any truth component is a
//! false object.

/// Bounding box and area of a set of positions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Extent {
    /// First and last row.
    pub rows: (usize, usize),
    /// First and last column.
    pub cols: (usize, usize),
    /// Positions in the set.
    pub area: usize,
}

impl Extent {
    pub fn of(px: &[(usize, usize)]) -> Option<Extent> {
        let first = px.first()?;
        let mut e = Extent {
            rows: (first.0, first.0),
            cols: (first.1, first.1),
            area: px.len(),
        };
        for &(r, c) in px {
            e.rows = (e.rows.0.min(r), e.rows.1.max(r));
            e.cols = (e.cols.0.min(c), e.cols.1.max(c));
        }
        Some(e)
    }

    /// Rows spanned.
    pub fn height(&self) -> usize {
        self.rows.1 - self.rows.0 + 1
    }

    /// Columns spanned.
    pub fn width(&self) -> usize {
        self.cols.1 - self.cols.0 + 1
    }

    /// The extent of the defect behind a detected object: one position less
    /// on each side (at least one position). The gradient (Eq. 1) compares
    /// the two neighbours of a position, so the positions just outside a
    /// defect, one of whose neighbours lies in it, score as high as its
    /// edge: a detected object is one position wider on each side than
    /// the defect. The area is not corrected.
    pub fn stencil_corrected(&self) -> Extent {
        let shrink = |(a, b): (usize, usize)| {
            if b >= a + 2 {
                (a + 1, b - 1)
            } else {
                let m = (a + b) / 2;
                (m, m)
            }
        };
        Extent {
            rows: shrink(self.rows),
            cols: shrink(self.cols),
            area: self.area,
        }
    }
}

/// One truth component and what detection made of it.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthObject {
    pub truth: Extent,
    /// Detected objects overlapping it (0 = missed).
    pub objects: usize,
    /// Extent of the union of those objects (`None` if missed).
    pub detected: Option<Extent>,
    /// Peak score inside the union of the truth component and its objects.
    pub peak: f64,
}

impl TruthObject {
    pub fn found(&self) -> bool {
        self.objects > 0
    }

    /// Relative errors of the detected height, width and area against the
    /// truth's ((detected - truth) / truth), `None` if missed.
    pub fn size_error(&self) -> Option<(f64, f64, f64)> {
        self.error_of(self.detected?)
    }

    /// Relative errors of the stencil-corrected extent's height and width
    /// ([`Extent::stencil_corrected`]), `None` if missed.
    pub fn corrected_error(&self) -> Option<(f64, f64)> {
        let (h, w, _) = self.error_of(self.detected?.stencil_corrected())?;
        Some((h, w))
    }

    fn error_of(&self, d: Extent) -> Option<(f64, f64, f64)> {
        let rel = |a: usize, b: usize| (a as f64 - b as f64) / b as f64;
        Some((
            rel(d.height(), self.truth.height()),
            rel(d.width(), self.truth.width()),
            rel(d.area, self.truth.area),
        ))
    }
}

/// Object-level result of one score map against one truth mask.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectReport {
    pub threshold: f64,
    pub truth: Vec<TruthObject>,
    /// Detected objects overlapping no truth component.
    pub false_objects: Vec<Extent>,
    /// Detected objects in all.
    pub detected: usize,
}

impl ObjectReport {
    pub fn found(&self) -> usize {
        self.truth.iter().filter(|t| t.found()).count()
    }
}

/// Objects of `values` (rows x cols, NaN never detected) at `threshold`
/// against the components of `truth`.
pub fn evaluate(
    values: &[f64],
    truth: &[bool],
    rows: usize,
    cols: usize,
    threshold: f64,
) -> ObjectReport {
    let detected_mask: Vec<bool> = values.iter().map(|&v| v >= threshold).collect();
    let det = components(&detected_mask, rows, cols);
    let tru = components(truth, rows, cols);
    // Which detected object each position belongs to.
    let mut label = vec![usize::MAX; rows * cols];
    for (i, comp) in det.iter().enumerate() {
        for &(r, c) in comp {
            label[r * cols + c] = i;
        }
    }
    let mut matched = vec![false; det.len()];
    let truth_objects = tru
        .iter()
        .map(|comp| {
            let mut hit: Vec<usize> = comp
                .iter()
                .map(|&(r, c)| label[r * cols + c])
                .filter(|&l| l != usize::MAX)
                .collect();
            hit.sort_unstable();
            hit.dedup();
            let union: Vec<(usize, usize)> =
                hit.iter().flat_map(|&l| det[l].iter().copied()).collect();
            for &l in &hit {
                matched[l] = true;
            }
            let peak = comp
                .iter()
                .chain(&union)
                .map(|&(r, c)| values[r * cols + c])
                .filter(|v| !v.is_nan())
                .fold(f64::NAN, f64::max);
            TruthObject {
                truth: Extent::of(comp).expect("components are never empty"),
                objects: hit.len(),
                detected: Extent::of(&union),
                peak,
            }
        })
        .collect();
    let false_objects = det
        .iter()
        .zip(&matched)
        .filter(|(_, m)| !**m)
        .filter_map(|(c, _)| Extent::of(c))
        .collect();
    ObjectReport {
        threshold,
        truth: truth_objects,
        false_objects,
        detected: det.len(),
    }
}

/// The report as JSON, sizes in positions and in mm at `pitch_mm`.
pub fn to_json(r: &ObjectReport, pitch_mm: f64) -> serde_json::Value {
    use serde_json::json;
    let ext = |e: &Extent| {
        json!({
            "rows": [e.rows.0, e.rows.1],
            "cols": [e.cols.0, e.cols.1],
            "area": e.area,
            "size_mm": [e.width() as f64 * pitch_mm, e.height() as f64 * pitch_mm],
        })
    };
    let num = |v: f64| {
        serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, serde_json::Value::Number)
    };
    let truth: Vec<serde_json::Value> = r
        .truth
        .iter()
        .map(|t| {
            let err = t.size_error();
            json!({
                "truth": ext(&t.truth),
                "found": t.found(),
                "objects": t.objects,
                "detected": t.detected.as_ref().map(ext),
                "peak": num(t.peak),
                "size_error": err.map(|(h, w, a)| json!({"rows": num(h), "cols": num(w), "area": num(a)})),
                "corrected": t.detected.map(|d| {
                    let c = d.stencil_corrected();
                    json!({"rows": [c.rows.0, c.rows.1], "cols": [c.cols.0, c.cols.1]})
                }),
                "corrected_error": t.corrected_error().map(|(h, w)| json!({"rows": num(h), "cols": num(w)})),
            })
        })
        .collect();
    json!({
        "threshold": num(r.threshold),
        "truth_objects": r.truth.len(),
        "found": r.found(),
        "missed": r.truth.len() - r.found(),
        "detected_objects": r.detected,
        "false_objects": r.false_objects.len(),
        "defects": truth,
        "false": r.false_objects.iter().map(ext).collect::<Vec<_>>(),
    })
}

/// 8-connected components of a mask, each as its list of (row, col), in
/// raster order of their first pixel.
pub fn components(mask: &[bool], rows: usize, cols: usize) -> Vec<Vec<(usize, usize)>> {
    let mut label = vec![usize::MAX; mask.len()];
    let mut out = Vec::new();
    for start in 0..mask.len() {
        if !mask[start] || label[start] != usize::MAX {
            continue;
        }
        let id = out.len();
        let mut comp = Vec::new();
        let mut stack = vec![start];
        label[start] = id;
        while let Some(i) = stack.pop() {
            let (r, c) = (i / cols, i % cols);
            comp.push((r, c));
            for nr in r.saturating_sub(1)..=(r + 1).min(rows - 1) {
                for nc in c.saturating_sub(1)..=(c + 1).min(cols - 1) {
                    let j = nr * cols + nc;
                    if mask[j] && label[j] == usize::MAX {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        comp.sort_unstable();
        out.push(comp);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(rows: usize, cols: usize, px: &[(usize, usize)]) -> Vec<bool> {
        let mut m = vec![false; rows * cols];
        for &(r, c) in px {
            m[r * cols + c] = true;
        }
        m
    }

    #[test]
    fn extent_of_a_set() {
        let e = Extent::of(&[(2, 3), (4, 1), (3, 3)]).unwrap();
        assert_eq!((e.rows, e.cols, e.area), ((2, 4), (1, 3), 3));
        assert_eq!((e.height(), e.width()), (3, 3));
        assert!(Extent::of(&[]).is_none());
        let c = e.stencil_corrected();
        assert_eq!((c.rows, c.cols, c.area), ((3, 3), (2, 2), 3));
        let thin = Extent {
            rows: (4, 5),
            cols: (7, 7),
            area: 2,
        }
        .stencil_corrected();
        assert_eq!((thin.rows, thin.cols), ((4, 4), (7, 7)));
    }

    #[test]
    fn found_split_missed_and_false_objects() {
        // 6x8. Truth: A = rows 1-2, cols 1-4 (area 8); B = (5, 7).
        // Detected (score 9 >= 5): {(1,1), (2,1)} and {(1,4), (2,4), (3,5)},
        // both on A (A found, split in two); (5, 0) on nothing (false);
        // B scores 4 (missed); NaN at (0, 7) is never detected.
        let (rows, cols) = (6, 8);
        let truth = mask(
            rows,
            cols,
            &[
                (1, 1),
                (1, 2),
                (1, 3),
                (1, 4),
                (2, 1),
                (2, 2),
                (2, 3),
                (2, 4),
                (5, 7),
            ],
        );
        let mut v = vec![1.0; rows * cols];
        for (r, c) in [(1, 1), (2, 1), (1, 4), (2, 4), (3, 5), (5, 0)] {
            v[r * cols + c] = 9.0;
        }
        v[5 * cols + 7] = 4.0;
        v[7] = f64::NAN;
        let rep = evaluate(&v, &truth, rows, cols, 5.0);
        assert_eq!((rep.detected, rep.found(), rep.truth.len()), (3, 1, 2));
        let a = &rep.truth[0];
        assert_eq!(a.objects, 2);
        assert_eq!(
            a.detected,
            Some(Extent {
                rows: (1, 3),
                cols: (1, 5),
                area: 5
            })
        );
        assert_eq!(a.size_error(), Some((0.5, 0.25, -0.375)));
        // One position less on each side: rows 2-2 (height 1), cols 2-4 (width 3).
        assert_eq!(a.corrected_error(), Some((-0.5, -0.25)));
        assert_eq!(a.peak, 9.0);
        let b = &rep.truth[1];
        assert!(!b.found() && b.detected.is_none() && b.size_error().is_none());
        assert_eq!(b.peak, 4.0);
        assert_eq!(
            rep.false_objects,
            vec![Extent {
                rows: (5, 5),
                cols: (0, 0),
                area: 1
            }]
        );
        // At the score itself a position counts (>=, the board's rule).
        assert_eq!(evaluate(&v, &truth, rows, cols, 9.0).detected, 3);
        assert_eq!(evaluate(&v, &truth, rows, cols, 9.5).detected, 0);
    }

    #[test]
    fn components_are_eight_connected() {
        // Two diagonal pixels form one component; a far pixel another.
        #[rustfmt::skip]
        let mask = [
            true,  false, false, false,
            false, true,  false, false,
            false, false, false, true,
        ];
        let c = components(&mask, 3, 4);
        assert_eq!(c, vec![vec![(0, 0), (1, 1)], vec![(2, 3)]]);
    }
}
