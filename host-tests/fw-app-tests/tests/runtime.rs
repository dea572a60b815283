//! The scoring side's loop (`cvm_fw_app::runtime`) with the command
//! channel's control: settings changed mid-scan rest in the control until
//! the scan ends, then reach the pipeline and the outputs in the same step
//! (the first beam of the next scan), and the scan under way keeps its
//! settings, its lines the reference's. Beams come through the shared
//! acquisition log and frame buffers (`frames`), lines through the shared
//! queue's sink (`queue`), as on the boards.

use core::cell::RefCell;

use cvm_core::command::{Capacity, Key, Request, Store, encode_request};
use cvm_core::pipeline::Pipeline;
use cvm_core::protocol::{LineSink, Priority, ResetCause};
use cvm_core::settings::{Outputs, RejectMode};
use cvm_fw_app::acquire::Acquisition;
use cvm_fw_app::control::{Control, Effect};
use cvm_fw_app::driver::ScanDriver;
use cvm_fw_app::frames::{Beams, SampleBuffers, SharedLog};
use cvm_fw_app::outputs::{Asserted, Change, OutputLogic};
use cvm_fw_app::queue::{LineQueue, QueueSink, SharedQueue};
use cvm_fw_app::runtime::{Pins, Runtime};
use cvm_fw_app_tests::{MAX_COLS, Scan, reference};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;

const CAP: Capacity = Capacity {
    max_cols: MAX_COLS as u16,
    max_rows: 1000,
    max_dcap: 16,
    max_pulse_us: 65536,
};

#[derive(Default)]
struct Replies(Vec<Vec<u8>>);
impl LineSink for Replies {
    fn line(&mut self, line: &[u8], _p: Priority) {
        self.0.push(line.to_vec());
    }
}

/// What the runtime asked of the pins, with the number of beams the board
/// had read when it did.
#[derive(Debug, PartialEq)]
enum Pin {
    Change(usize, Change),
    Configure(usize, Outputs, Asserted),
}

struct Recorder<'p> {
    log: &'p RefCell<Vec<Pin>>,
    beams: &'p core::cell::Cell<usize>,
}

impl Pins for Recorder<'_> {
    fn change(&mut self, change: Change) {
        self.log
            .borrow_mut()
            .push(Pin::Change(self.beams.get(), change));
    }
    fn configure(&mut self, settings: &Outputs, now: Asserted) {
        self.log
            .borrow_mut()
            .push(Pin::Configure(self.beams.get(), *settings, now));
    }
}

fn ask(control: &RefCell<Control>, id: u32, r: Request) {
    let mut req = Replies::default();
    encode_request(id, &r, &mut req);
    let line = req.0.remove(0);
    let mut out = Replies::default();
    let effect = control.borrow_mut().line(&line[..line.len() - 1], &mut out);
    assert_eq!(effect, Effect::None);
    assert_eq!(out.0.len(), 1, "one reply");
    assert!(out.0[0].starts_with(b"A,"), "answered, not refused");
}

fn configures(log: &RefCell<Vec<Pin>>) -> Vec<(usize, Outputs)> {
    log.borrow()
        .iter()
        .filter_map(|p| match p {
            Pin::Configure(beam, o, _) => Some((*beam, *o)),
            Pin::Change(..) => None,
        })
        .collect()
}

#[test]
fn settings_changed_mid_scan_take_effect_with_the_next_scan_on_pipeline_and_pins_together() {
    let scan = Scan::generate(3, 3, 4, 2, 11, (1, 2));
    let scorer = scan.scorer();
    let (mut a, mut b) = scan.row_buffers();
    let settings = scan.settings(&scorer, true);
    let old_thr = settings.threshold;
    let new_thr = old_thr + 12_345;
    let pipeline = Pipeline::<MAX_COLS>::new(&scorer, settings, &mut a, &mut b).unwrap();
    let mut driver = ScanDriver::new(pipeline, scan.cols, scan.rows);
    let boot = cvm_core::Boot {
        store: Store::Empty,
        ..cvm_core::Boot::power_on(cvm_core::VERSION)
    };
    let control = RefCell::new(Control::new(settings, boot, CAP, (3, 3), None));

    let log: SharedLog<NoopRawMutex, 2, 16> = Mutex::new(RefCell::new(Acquisition::new()));
    let bufs = SampleBuffers::<2, 9>::new();
    let mut beams = Beams {
        log: &log,
        bufs: &bufs,
        cells: 9,
    };
    let queue: SharedQueue<NoopRawMutex, 8192> = Mutex::new(RefCell::new(LineQueue::new(2048)));
    let mut lines = QueueSink(&queue);
    let mut replies = Replies::default();
    let pins = RefCell::new(Vec::new());
    let read = core::cell::Cell::new(0usize);
    let outputs = OutputLogic::start(settings.outputs, ResetCause::PowerOn);
    let mut rt = Runtime::new(
        &mut driver,
        outputs,
        Recorder {
            log: &pins,
            beams: &read,
        },
        Some(&control),
    );

    let per_scan = (scan.cols * scan.rows) as usize;
    let finished = core::cell::Cell::new(0usize);
    let mut beam = |rt: &mut Runtime<'_, '_, MAX_COLS, Recorder<'_>>, k: usize| {
        let sync = k.is_multiple_of(scan.cols as usize);
        let buf = log
            .lock(|l| l.borrow_mut().drdy(sync))
            .expect("a free buffer");
        // SAFETY: `buf` is Filling: this test owns it until `read_done`.
        unsafe { bufs.buffer(buf) }.copy_from_slice(scan.frame(k));
        log.lock(|l| l.borrow_mut().read_done(buf, true));
        read.set(k + 1);
        while let Some(f) = rt.step(&mut beams, &mut lines, &mut replies) {
            finished.set(finished.get() + usize::from(f));
        }
    };

    // The first scan's first row, with the start's settings (the control
    // starts pending: they are applied once, with the first beam).
    for k in 0..4 {
        beam(&mut rt, k);
    }
    assert_eq!(configures(&pins), vec![(1, settings.outputs)]);

    // Mid-scan: a threshold, a pulse width and row mode.
    ask(&control, 1, Request::Set(Key::Threshold, new_thr));
    ask(&control, 2, Request::Set(Key::Pulse, 500));
    ask(&control, 3, Request::Set(Key::RejectMode, 1));
    // Pending in the control only; the pipeline keeps the scan's.
    assert_eq!(control.borrow().settings().threshold, new_thr);
    assert_eq!(rt.driver().settings().threshold, old_thr);

    for k in 4..per_scan {
        beam(&mut rt, k);
        assert_eq!(rt.driver().settings().threshold, old_thr, "beam {k}");
    }
    assert_eq!(finished.get(), 1);
    assert_eq!(configures(&pins).len(), 1, "nothing applied mid-scan");

    // The scan under way kept its settings: its lines are the reference's.
    let mut sent = Vec::new();
    let mut line = [0u8; cvm_core::protocol::MAX_LINE];
    while let Some(n) = queue.lock(|q| q.borrow_mut().pop_into(&mut line)) {
        sent.push(String::from_utf8(line[..n].to_vec()).unwrap());
    }
    assert_eq!(sent, reference(&scan, true, &[], 0));

    // The next scan's first beam: pipeline and pins take the new settings
    // in that step, and nothing is left pending.
    beam(&mut rt, per_scan);
    assert_eq!(rt.driver().settings().threshold, new_thr);
    assert_eq!(rt.driver().settings().outputs.pulse_us, 500);
    let c = configures(&pins);
    assert_eq!(c.len(), 2);
    assert_eq!(c[1].0, per_scan + 1);
    assert_eq!(c[1].1.reject_mode, RejectMode::Row);
    assert_eq!(c[1].1.pulse_us, 500);
    assert_eq!(control.borrow_mut().take_changed(), None);
    assert!(replies.0.is_empty());
}
