//! The part's verdict: what a PLC or a reject gate acts on, decided once
//! at the scan's end from the same totals and objects the lines report,
//! so that the end line (`verdict=`) and a board's REJECT pin cannot
//! disagree.

use crate::objects::Object;
use crate::settings::Outputs;
use crate::stream::Totals;

/// Why a scan could not inspect its part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fault {
    /// Positions without data (beams lost to an overrun, an SPI or DMA
    /// error, a missing DRDY, a scan cut short) beyond the limit.
    Missing,
    /// Frames scored at a wrong position beyond the limit.
    Misplaced,
    /// Frames of the wrong length, repeated or beyond the last column.
    Frames,
}

/// A scan's verdict on its part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Verdict {
    /// Inspected completely, no object that counts.
    Good,
    /// Inspected completely, at least one object that counts (or defects
    /// that no object could hold).
    Objects,
    /// Not inspected properly: rejected, never passed.
    Fault(Fault),
}

impl Verdict {
    /// Every verdict, in the order of the protocol document.
    pub const ALL: [Verdict; 5] = [
        Verdict::Good,
        Verdict::Objects,
        Verdict::Fault(Fault::Missing),
        Verdict::Fault(Fault::Misplaced),
        Verdict::Fault(Fault::Frames),
    ];

    /// The value of the end line's `verdict=`.
    pub const fn as_str(self) -> &'static str {
        match self {
            Verdict::Good => "good",
            Verdict::Objects => "obj",
            Verdict::Fault(Fault::Missing) => "fault-missing",
            Verdict::Fault(Fault::Misplaced) => "fault-misplaced",
            Verdict::Fault(Fault::Frames) => "fault-frames",
        }
    }

    /// The verdict whose `verdict=` value is `s`.
    pub fn parse(s: &[u8]) -> Option<Self> {
        Verdict::ALL
            .into_iter()
            .find(|v| v.as_str().as_bytes() == s)
    }

    /// The part is to be rejected: objects or a fault.
    pub const fn rejects(self) -> bool {
        !matches!(self, Verdict::Good)
    }

    /// The scan was faulty: the sensor is not ready.
    pub const fn is_fault(self) -> bool {
        matches!(self, Verdict::Fault(_))
    }

    /// The verdict of a scan with these totals, of which `counted`
    /// objects passed [`counts`]. A fault outranks objects: a part that
    /// was not inspected completely may hide more than it showed.
    pub fn of(t: &Totals, counted: u32, o: &Outputs) -> Self {
        if t.bad > 0 || t.rejected > 0 || t.extra > 0 {
            Verdict::Fault(Fault::Frames)
        } else if t.missing > o.max_missing {
            Verdict::Fault(Fault::Missing)
        } else if t.misplaced > o.max_misplaced {
            Verdict::Fault(Fault::Misplaced)
        } else if counted > 0 || t.unobjected > 0 {
            // Defects left out of every object have no area to compare:
            // they reject.
            Verdict::Objects
        } else {
            Verdict::Good
        }
    }
}

/// What the lines about to be encoded will report, told to the line sink
/// before them ([`crate::protocol::LineSink::ahead`]): a board acts on it
/// at once (its REJECT output), and the lines, which take far longer to
/// encode, follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ahead {
    /// The scan's verdict, as soon as it is known: right after its last
    /// beam when the totals decide it (a fault, an object that counted
    /// already, or rules under which every object counts), else once the
    /// labeller has run over the last rows. Always before the last rows'
    /// lines, and before [`Ahead::End`].
    Verdict(Verdict),
    /// A row is about to go out: `rows` rows of the scan are then out,
    /// and it closes `closed` objects that count.
    Row { rows: u32, closed: u32 },
    /// The scan ends with `verdict`; its end closes `closed` more objects
    /// that count. Told before the last rows' lines.
    End { closed: u32, verdict: Verdict },
}

impl Verdict {
    /// The verdict of a scan with these totals when it does not depend on
    /// which objects its last rows form (`None` when it does): a fault; an
    /// object that counted already (`counted`), or one still open that
    /// counts already as it stands (`open_counts`: its area and peak only
    /// grow); or rules under which every object counts (every object has
    /// an area of at least 1 and a peak of at least `2^16`), when any
    /// defect position (`defects`, all of the scan's) makes an object or
    /// is left out of one, and both reject. Equal to [`Verdict::of`] with
    /// the objects' final counts.
    pub fn without_objects(
        t: &Totals,
        defects: u32,
        counted: u32,
        open_counts: bool,
        o: &Outputs,
    ) -> Option<Self> {
        let v = Verdict::of(t, counted.saturating_add(open_counts as u32), o);
        if v.is_fault() || counted > 0 || open_counts {
            return Some(v);
        }
        (o.min_area <= 1 && o.min_strength <= 1 << 16).then_some(if defects > 0 {
            Verdict::Objects
        } else {
            Verdict::Good
        })
    }
}

/// Whether object `obj` is large or strong enough to reject its part.
pub fn counts(obj: &Object, o: &Outputs) -> bool {
    obj.area >= o.min_area && obj.peak >= o.min_strength
}
