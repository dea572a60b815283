//! The command channel (docs/commands.md): requests a
//! host sends to the board on the serial link, and the replies the board
//! sends back between its result lines. Lines are framed and checksummed
//! like the result lines (`<type>,<fields>*XXXX\n`, the same CRC-16, at
//! most [`MAX_LINE`] bytes); a request is a `C` line, a reply an `A`
//! line, and each request carries an id that its reply echoes.
//!
//! The codec is the line level only, and runs on the target: encoders
//! write into fixed buffers, parsers borrow from the line, nothing
//! allocates and no input makes it panic. What a request does to the
//! board's settings (when a change takes effect, what `save` writes) is
//! the firmware's. `reader` cuts the received bytes into lines, `key`
//! names the runtime settings and checks their values, `request` and
//! `reply` are the two directions, `status` the longest reply, `refusal`
//! the reasons a request is refused, and `wire` the field reading and the
//! framing check they share.

mod key;
mod reader;
mod refusal;
mod reply;
mod request;
mod status;
mod wire;

pub use crate::calibration::Calibration;
pub use crate::settings::{Capacity, KEYS, Key, Kind, SETTINGS, Spec};
pub use crate::settings::{Source, Store};
pub use key::conflict;
pub use reader::{Event, IDLE_GAP_MS, LineReader, LinkError};
pub use refusal::Refusal;
pub use reply::{Reply, encode_reply, parse_reply};
pub use request::{Request, encode_request, parse_request};
pub use status::{LastScan, Status};
pub use wire::{
    MAX_CALIBRATION_RATE_PPM, MAX_CALIBRATION_SCANS, MAX_LINE, REPLY, REQUEST, VERSION,
};
