//! READY and REJECT logic (`cvm_fw_app::outputs`): the states the board
//! writes to its pins after each scoring step, against the rules of
//! docs/firmware.md ("READY and REJECT outputs") written out by hand.

use cvm_core::protocol::ResetCause;
use cvm_core::settings::{Outputs, RejectMode};
use cvm_core::{Fault, Verdict};
use cvm_fw_app::outputs::{Asserted, Change, OutputLogic, Progress, level};

fn progress(begun: u32, finished: u32, verdict: Option<Verdict>, faulty: bool) -> Progress {
    Progress {
        begun,
        finished,
        verdict,
        faulty,
        rows: 0,
    }
}

const fn asserted(ready: bool, reject: bool) -> Asserted {
    Asserted { ready, reject }
}

#[test]
fn power_on_is_ready_any_other_start_is_not_and_rejects_the_cut_part() {
    let s = Outputs::DEFAULT;
    assert_eq!(
        OutputLogic::start(s, ResetCause::PowerOn).asserted(),
        asserted(true, false)
    );
    for cause in [
        ResetCause::Watchdog,
        ResetCause::Software,
        ResetCause::Pin,
        ResetCause::Other,
    ] {
        assert_eq!(
            OutputLogic::start(s, cause).asserted(),
            asserted(false, true),
            "{cause:?}"
        );
    }
    // In row mode no part is held rejected.
    let row = Outputs {
        reject_mode: RejectMode::Row,
        pulse_us: 500,
        ..s
    };
    assert_eq!(
        OutputLogic::start(row, ResetCause::Watchdog).asserted(),
        asserted(false, false)
    );
}

#[test]
fn part_mode_holds_reject_from_the_verdict_to_the_next_scan() {
    let mut o = OutputLogic::start(Outputs::DEFAULT, ResetCause::PowerOn);
    // A scan begins, beams go by: nothing changes.
    assert_eq!(o.step(progress(1, 0, None, false), 0), None);
    assert_eq!(o.step(progress(1, 0, None, false), 3), None);
    // It ends with objects: REJECT, READY stays.
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
        Some(Change {
            now: asserted(true, true),
            pulses: 0
        })
    );
    // Held while idle; released when the next scan begins.
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
        None
    );
    assert_eq!(
        o.step(progress(2, 1, Some(Verdict::Objects), false), 0),
        Some(Change {
            now: asserted(true, false),
            pulses: 0
        })
    );
    // A good part: nothing to change.
    assert_eq!(o.step(progress(2, 2, Some(Verdict::Good), false), 0), None);
}

#[test]
fn a_fault_drops_ready_at_once_and_only_a_clean_scan_restores_it() {
    let mut o = OutputLogic::start(Outputs::DEFAULT, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    // Mid-scan, the totals already make the scan faulty.
    assert_eq!(
        o.step(progress(1, 0, None, true), 0),
        Some(Change {
            now: asserted(false, false),
            pulses: 0
        })
    );
    let fault = Verdict::Fault(Fault::Missing);
    assert_eq!(
        o.step(progress(1, 1, Some(fault), false), 0),
        Some(Change {
            now: asserted(false, true),
            pulses: 0
        })
    );
    // The next scan begins: the part is released, READY still down.
    assert_eq!(
        o.step(progress(2, 1, Some(fault), false), 0),
        Some(Change {
            now: asserted(false, false),
            pulses: 0
        })
    );
    // It ends with objects but no fault: READY back, the part rejected.
    assert_eq!(
        o.step(progress(2, 2, Some(Verdict::Objects), false), 0),
        Some(Change {
            now: asserted(true, true),
            pulses: 0
        })
    );
}

#[test]
fn after_a_watchdog_reset_ready_waits_for_a_clean_scan() {
    let mut o = OutputLogic::start(Outputs::DEFAULT, ResetCause::Watchdog);
    assert_eq!(
        o.step(progress(1, 0, None, false), 0),
        Some(Change {
            now: asserted(false, false),
            pulses: 0
        })
    );
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Good), false), 0),
        Some(Change {
            now: asserted(true, false),
            pulses: 0
        })
    );
}

#[test]
fn pulses_part_mode_with_a_width_and_row_mode() {
    let s = Outputs {
        pulse_us: 2_000,
        ..Outputs::DEFAULT
    };
    let mut o = OutputLogic::start(s, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
        Some(Change {
            now: asserted(true, false),
            pulses: 1
        })
    );
    let row = Outputs {
        reject_mode: RejectMode::Row,
        ..s
    };
    let mut o = OutputLogic::start(row, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    assert_eq!(
        o.step(progress(1, 0, None, false), 2),
        Some(Change {
            now: asserted(true, false),
            pulses: 2
        })
    );
    // The scan's verdict adds no pulse of its own in row mode.
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
        None
    );
}

#[test]
fn pin_levels_follow_the_polarity() {
    assert!(level(true, true));
    assert!(!level(false, true));
    assert!(!level(true, false));
    assert!(level(false, false));
    // The default READY is active high: an unpowered board or a broken
    // wire (the PLC input's pull-down: low) reads "not ready".
    const { assert!(Outputs::DEFAULT.ready_high) };
}

#[test]
fn row_mode_delays_each_rows_pulses_by_the_set_rows() {
    let s = Outputs {
        reject_mode: RejectMode::Row,
        pulse_us: 500,
        row_delay: 2,
        ..Outputs::DEFAULT
    };
    let mut o = OutputLogic::start(s, ResetCause::PowerOn);
    let at = |rows: u32, finished: u32| Progress {
        begun: 1,
        finished,
        verdict: None,
        faulty: false,
        rows,
    };
    o.step(at(0, 0), 0);
    let pulse = |n| {
        Some(Change {
            now: asserted(true, false),
            pulses: n,
        })
    };
    // Row 4 goes out (5 rows out) and closes one object: due when 7
    // rows are out.
    assert_eq!(o.step(at(5, 0), 1), None);
    // Row 5 closes two more: due at 8.
    assert_eq!(o.step(at(6, 0), 2), None);
    assert_eq!(o.step(at(7, 0), 0), pulse(1));
    assert_eq!(o.step(at(8, 0), 0), pulse(2));
    // A closure near the end of the scan: its pulse comes with the end,
    // when no row is left to count the delay.
    assert_eq!(o.step(at(9, 0), 1), None);
    assert_eq!(o.step(at(10, 1), 0), pulse(1));
}

/// The news the pipeline tells ahead of its lines moves the outputs as
/// the scoring step's progress would, and the step after it, which the
/// board runs with no closures, finds nothing left to do: no edge twice,
/// no pulse twice.
#[test]
fn news_ahead_of_the_lines_moves_the_outputs_once() {
    use cvm_core::verdict::Ahead;
    // Part mode, held: REJECT goes up on the news of a rejecting end.
    let mut o = OutputLogic::start(Outputs::DEFAULT, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    assert_eq!(o.ahead(Ahead::Row { rows: 1, closed: 1 }), None);
    assert_eq!(
        o.ahead(Ahead::End {
            closed: 0,
            verdict: Verdict::Objects
        }),
        Some(Change {
            now: asserted(true, true),
            pulses: 0
        })
    );
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
        None
    );
    // A fault: READY drops with the news, REJECT goes up.
    o.step(progress(2, 1, Some(Verdict::Objects), false), 0);
    let fault = Verdict::Fault(Fault::Missing);
    assert_eq!(
        o.ahead(Ahead::End {
            closed: 0,
            verdict: fault
        }),
        Some(Change {
            now: asserted(false, true),
            pulses: 0
        })
    );
    assert_eq!(o.step(progress(2, 2, Some(fault), false), 0), None);
    // Part mode with a width: one pulse, not two.
    let s = Outputs {
        pulse_us: 300,
        ..Outputs::DEFAULT
    };
    let mut o = OutputLogic::start(s, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    let end = Ahead::End {
        closed: 1,
        verdict: Verdict::Objects,
    };
    assert_eq!(o.ahead(end).map(|c| c.pulses), Some(1));
    assert_eq!(
        o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
        None
    );
    // Row mode, delay 1: a row's closures pulse when the next row's news
    // comes, the end's closures with the end.
    let s = Outputs {
        reject_mode: RejectMode::Row,
        pulse_us: 300,
        row_delay: 1,
        ..Outputs::DEFAULT
    };
    let mut o = OutputLogic::start(s, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    assert_eq!(o.ahead(Ahead::Row { rows: 1, closed: 2 }), None);
    let at = |rows| Progress {
        rows,
        ..progress(1, 0, None, false)
    };
    assert_eq!(o.step(at(1), 0), None);
    assert_eq!(
        o.ahead(Ahead::Row { rows: 2, closed: 0 }).map(|c| c.pulses),
        Some(2)
    );
    assert_eq!(o.step(at(2), 0), None);
    assert_eq!(o.ahead(Ahead::Row { rows: 3, closed: 1 }), None);
    assert_eq!(o.ahead(end).map(|c| c.pulses), Some(2));
    assert_eq!(
        o.step(
            Progress {
                rows: 3,
                ..progress(1, 1, Some(Verdict::Objects), false)
            },
            0
        ),
        None
    );
}

/// The verdict told as soon as the totals decide it, before the end's
/// news: part mode's REJECT and READY move then, and neither the end nor
/// the step after it moves them again; row mode's pulses still wait for
/// the end's closures.
#[test]
fn the_verdict_told_before_the_end_acts_once() {
    use cvm_core::verdict::Ahead;
    for pulse_us in [0, 300] {
        let s = Outputs {
            pulse_us,
            ..Outputs::DEFAULT
        };
        let mut o = OutputLogic::start(s, ResetCause::PowerOn);
        o.step(progress(1, 0, None, false), 0);
        let told = o.ahead(Ahead::Verdict(Verdict::Objects)).unwrap();
        assert_eq!(told.now.reject, pulse_us == 0);
        assert_eq!(told.pulses, u32::from(pulse_us > 0));
        let end = Ahead::End {
            closed: 2,
            verdict: Verdict::Objects,
        };
        assert_eq!(o.ahead(end), None);
        assert_eq!(
            o.step(progress(1, 1, Some(Verdict::Objects), false), 0),
            None
        );
        // The next part starts released and is judged afresh.
        o.step(progress(2, 1, Some(Verdict::Objects), false), 0);
        let fault = Verdict::Fault(Fault::Frames);
        let told = o.ahead(Ahead::Verdict(fault)).unwrap();
        assert!(!told.now.ready);
        assert_eq!(told.pulses, u32::from(pulse_us > 0));
    }
    let row = Outputs {
        reject_mode: RejectMode::Row,
        pulse_us: 300,
        ..Outputs::DEFAULT
    };
    let mut o = OutputLogic::start(row, ResetCause::PowerOn);
    o.step(progress(1, 0, None, false), 0);
    assert_eq!(o.ahead(Ahead::Verdict(Verdict::Objects)), None);
    let end = Ahead::End {
        closed: 2,
        verdict: Verdict::Objects,
    };
    assert_eq!(o.ahead(end).map(|c| c.pulses), Some(2));
}
