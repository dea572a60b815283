//! The output queue against a plain model of its documented policy
//! (`cvm_fw_app::queue` module docs): a line costs two length bytes plus
//! its bytes; a droppable line is accepted only if `reserve` bytes stay
//! free after it, a keep line whenever it fits; refused lines are counted
//! by priority; lines come out whole, in order, cut to the caller's buffer;
//! `keep_room` is "the whole reserve is free"; `high_water` is the most
//! bytes ever queued.

use std::collections::VecDeque;

use cvm_core::protocol::{LineSink, Priority};
use cvm_fw_app::queue::{LineQueue, QueueCounts};
use proptest::prelude::*;

const CAP: usize = 64;

struct Model {
    reserve: usize,
    lines: VecDeque<Vec<u8>>,
    counts: QueueCounts,
}

impl Model {
    fn used(&self) -> usize {
        self.lines.iter().map(|l| 2 + l.len()).sum()
    }

    fn push(&mut self, line: &[u8], p: Priority) -> bool {
        let free = CAP - self.used();
        let room = match p {
            Priority::Keep => 2 + line.len(),
            Priority::Droppable => 2 + line.len() + self.reserve,
        };
        if free < room {
            match p {
                Priority::Keep => self.counts.dropped_keep += 1,
                Priority::Droppable => self.counts.dropped_scores += 1,
            }
            return false;
        }
        self.lines.push_back(line.to_vec());
        self.counts.accepted += 1;
        self.counts.high_water = self.counts.high_water.max(self.used());
        true
    }
}

#[derive(Clone, Debug)]
enum Op {
    Push(Vec<u8>, bool),
    Sink(Vec<u8>, bool),
    Pop(usize),
}

fn op() -> impl Strategy<Value = Op> {
    let line = prop::collection::vec(any::<u8>(), 0..40);
    prop_oneof![
        3 => (line.clone(), any::<bool>()).prop_map(|(l, k)| Op::Push(l, k)),
        1 => (line, any::<bool>()).prop_map(|(l, k)| Op::Sink(l, k)),
        3 => (0usize..48).prop_map(Op::Pop),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn queue_follows_its_policy(reserve in 0usize..80, ops in prop::collection::vec(op(), 1..120)) {
        let mut q: LineQueue<CAP> = LineQueue::new(reserve);
        let mut m = Model { reserve: reserve.min(CAP), lines: VecDeque::new(), counts: QueueCounts::default() };
        for o in ops {
            match o {
                Op::Push(l, keep) => {
                    let p = if keep { Priority::Keep } else { Priority::Droppable };
                    prop_assert_eq!(q.push(&l, p), m.push(&l, p));
                }
                Op::Sink(l, keep) => {
                    let p = if keep { Priority::Keep } else { Priority::Droppable };
                    q.line(&l, p);
                    m.push(&l, p);
                }
                Op::Pop(n) => {
                    let mut out = vec![0xA5u8; n];
                    let got = q.pop_into(&mut out);
                    match m.lines.pop_front() {
                        None => prop_assert_eq!(got, None),
                        Some(line) => {
                            let k = line.len().min(n);
                            prop_assert_eq!(got, Some(k));
                            prop_assert_eq!(&out[..k], &line[..k]);
                            // Nothing beyond the line is written.
                            prop_assert!(out[k..].iter().all(|&b| b == 0xA5));
                        }
                    }
                }
            }
            let used = m.used();
            prop_assert_eq!(q.counts(), &m.counts);
            prop_assert_eq!(q.free(), CAP - used);
            prop_assert_eq!(q.is_empty(), m.lines.is_empty());
            prop_assert_eq!(q.keep_room(), CAP - used >= m.reserve);
            prop_assert_eq!(q.dropped(), m.counts.dropped_keep + m.counts.dropped_scores);
        }
    }
}

/// The exact boundaries: a droppable line that leaves exactly `reserve`
/// bytes free is accepted, one byte more is not; a keep line that fills the
/// queue exactly is accepted; `keep_room` holds with exactly `reserve`
/// bytes free.
#[test]
fn boundaries_are_inclusive() {
    let mut q: LineQueue<50> = LineQueue::new(20);
    assert_eq!(LineQueue::<50>::cost(10), 12);
    // 50 - 28 - 2 = 20 free after it: accepted.
    assert!(!q.push(&[1; 29], Priority::Droppable));
    assert!(q.push(&[1; 28], Priority::Droppable));
    assert_eq!(q.free(), 20);
    assert!(q.keep_room());
    assert!(q.push(&[], Priority::Keep));
    assert!(!q.keep_room());
    // 18 free: a keep line of cost 18 fits exactly, one of 19 would not.
    assert!(!q.push(&[2; 17], Priority::Keep));
    assert!(q.push(&[2; 16], Priority::Keep));
    assert_eq!(q.free(), 0);
    assert_eq!(q.counts().high_water, 50);
    let mut out = [0u8; 64];
    assert_eq!(q.pop_into(&mut out), Some(28));
    assert_eq!(q.pop_into(&mut out), Some(0));
    assert_eq!(q.pop_into(&mut out), Some(16));
    assert_eq!(&out[..16], &[2; 16]);
    assert!(q.is_empty());
    assert_eq!(q.counts().high_water, 50);
}

/// A reserve larger than the queue is clamped to it: the queue then takes
/// keep lines only, and `keep_room` holds exactly when it is empty.
#[test]
fn reserve_is_clamped_to_the_capacity() {
    let mut q: LineQueue<30> = LineQueue::new(1000);
    assert!(q.keep_room());
    assert!(!q.push(&[], Priority::Droppable));
    assert!(q.push(&[7; 28], Priority::Keep));
    assert!(!q.keep_room());
    let mut out = [0u8; 4];
    // Cut to the caller's buffer; the rest of the line is consumed.
    assert_eq!(q.pop_into(&mut out), Some(4));
    assert!(q.keep_room() && q.is_empty());
    assert_eq!(q.pop_into(&mut out), None);
}

/// The length prefix is 16 bits: the longest line it can describe goes
/// through intact, a longer one is refused and counted even when the
/// queue has room for it.
#[test]
fn lines_longer_than_the_length_prefix_are_refused() {
    const BIG: usize = 65_600;
    let mut q: Box<LineQueue<BIG>> = Box::new(LineQueue::new(0));
    let long: Vec<u8> = (0..65_536u32).map(|i| (i % 251) as u8).collect();
    assert!(!q.push(&long, Priority::Keep));
    assert_eq!(q.counts().dropped_keep, 1);
    assert!(q.is_empty());
    assert!(q.push(&long[..65_535], Priority::Keep));
    let mut out = vec![0u8; 70_000];
    assert_eq!(q.pop_into(&mut out), Some(65_535));
    assert_eq!(&out[..65_535], &long[..65_535]);
}
