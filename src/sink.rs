//! The line sink both boards give the pipeline: each line goes into the
//! bounded output queue that the UART task drains.

use core::cell::RefCell;

use cvm_core::protocol::{LineSink, Priority};
use cvm_fw_app::driver::CountingSink;
use cvm_fw_app::queue::LineQueue;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;

pub type SharedQueue<const N: usize> = Mutex<ThreadModeRawMutex, RefCell<LineQueue<N>>>;

pub struct QueueSink<const N: usize>(pub &'static SharedQueue<N>);

impl<const N: usize> LineSink for QueueSink<N> {
    fn line(&mut self, line: &[u8], priority: Priority) {
        self.0.lock(|q| q.borrow_mut().push(line, priority));
    }
}

impl<const N: usize> CountingSink for QueueSink<N> {
    fn dropped(&self) -> u32 {
        self.0.lock(|q| q.borrow().dropped())
    }
}
